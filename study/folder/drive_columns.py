"""The columns of the canonical drive log (docs/contracts.md "Drive log"): the required ones, the optional ones by
type with their allowed values, and all of them in canonical order. Numbers are in SI units (``t`` s, ``s`` m, ``v``
and ``speed_limit`` m/s, forces N, ``p_batt`` W, ``grade`` rad)."""
from __future__ import annotations

REQUIRED = ("t", "s", "v", "segment", "speed_limit")
TL_STATES = ("green", "yellow", "red")
CONTROLLERS = ("rt", "cf", "none")
FLOAT_OPTIONAL = ("a", "grade", "ft", "fb", "p_batt", "d_tl", "leader_gap", "leader_v", "v_advice")
TEXT_OPTIONAL = {"tl_id": None, "tl_state": TL_STATES, "controller": CONTROLLERS}
BOOL_OPTIONAL = ("hud_in_band", "warning")
COLUMNS = REQUIRED + ("a", "grade", "ft", "fb", "p_batt", "tl_id", "tl_state", "d_tl", "leader_gap", "leader_v",
                      "v_advice", "controller", "hud_arrow", "hud_in_band", "warning")
