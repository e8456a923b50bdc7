"""Constants the paper fixes. Parameters the paper leaves open (vehicle data, weights, headways) live in
`pedas.params` with their sources; only values printed in the paper belong here."""
from __future__ import annotations

KMH = 1.0 / 3.6  # m/s per km/h

DT = 0.2  # s, MPC/control sample time Delta T (Sec. 3.3, eq. 3a-3d)
N_HORIZON = 20  # MPC prediction horizon N (Sec. 3.5)
SENSOR_RANGE = 100.0  # m, d_rel above which the reference-tracking MPC is engaged (Sec. 3.1)
STOP_DWELL = 3.0  # s, compulsory halt s_t at a stop sign (Sec. 3.2)

# speed correction v_corr when the safe distance is violated, eq. (11)
ALPHA1 = 0.008
ALPHA2 = -0.05
ALPHA3 = 0.4

HUD_BAND = 2.0 * KMH  # m/s, +-2 km/h band in which the driver coasts (Sec. 3.8)
HUD_TL_COUNTDOWN = 10.0  # s, TL remaining time shown when below this (Sec. 3.8)
HIGHWAY_MIN_SPEED = 80.0 * KMH  # m/s, minimum the participants had to keep on the highway (Sec. 4.3)
ROUTE_LENGTH = 13_200.0  # m, the study route (Sec. 4.3)
