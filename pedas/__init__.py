"""pEDAS simulation core: vehicle and power model, reference speeds (DP, green wave), the reference-tracking and
car-following MPCs on OSQP, controller switching, speed correction, HUD advisory, the SUMO route and traffic,
virtual drivers and the drive loop. Imports neither `study` nor `analysis`."""
