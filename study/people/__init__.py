"""Participants and the protocol they go through: the roster and its attributes (`participants`), the phase events
in protocol order (`protocol`), counterbalanced orders (`orders`), scheduling of sessions (`scheduling`, its
defaults in `defaults`) and exclusions (`exclusions`).

Imports `study.common`, `study.folder` and `study.store`.
"""
