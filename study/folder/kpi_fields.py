"""The drive KPIs' vocabulary: the sample columns they read, the built-in output columns and their thresholds.

Shared by the KPI query (:mod:`analysis.drives.kpis`) and the study's KPI declaration
(:mod:`study.folder.kpi_spec`), which both read it; neither needs the other for it.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

from pedas.constants import KMH

#: The columns of drive_samples the KPIs read.
KPI_COLUMNS = ("drive_id", "idx", "t", "s", "v", "segment", "speed_limit", "a", "p_batt",
               "tl_id", "tl_state", "d_tl")

#: Output columns of :func:`analysis.drives.kpis.kpis_from_relation`, in order.
KPI_FIELDS = ("drive_id", "segment", "n_intervals", "energy_wh", "distance_m", "trip_time_s", "mean_speed_mps",
              "wh_per_km", "violation_distance_m", "violation_share", "violation_events", "tl_crossed",
              "tl_crossed_green", "tl_crossed_yellow", "tl_crossed_red", "tl_green_passes", "red_stops", "stops",
              "rms_jerk", "mean_abs_a")


@dataclass(frozen=True)
class KpiParams:
    """Thresholds of the KPI definitions (module docstring); every value is documented in docs/kpis.md."""
    tol_abs: float = 3.0 * KMH      # m/s, absolute speeding tolerance (German enforcement deduction <= 100 km/h)
    tol_rel: float = 0.03           # share of the limit, tolerance above 100 km/h (same rule)
    min_event_s: float = 1.0        # s, a violation episode shorter than this is not an event
    v_stop: float = 0.5             # m/s, below = standing
    v_moving: float = 2.0           # m/s, above = moving (hysteresis for stop counting)
    red_stop_dist: float = 50.0     # m, stand-still closer than this to a red light's stop line = red stop

    def sql_params(self) -> dict:
        return asdict(self)


#: columns of drive_samples a SQL KPI may read besides the declared channels (types for the trial table)
SAMPLE_COLUMNS = {"drive_id": "BIGINT", "idx": "INTEGER", "t": "DOUBLE", "s": "DOUBLE", "v": "DOUBLE",
                  "segment": "VARCHAR", "speed_limit": "DOUBLE", "a": "DOUBLE", "grade": "DOUBLE", "ft": "DOUBLE",
                  "fb": "DOUBLE", "p_batt": "DOUBLE", "tl_id": "VARCHAR", "tl_state": "VARCHAR", "d_tl": "DOUBLE",
                  "leader_gap": "DOUBLE", "leader_v": "DOUBLE", "v_advice": "DOUBLE", "controller": "VARCHAR",
                  "hud_arrow": "TINYINT", "hud_in_band": "BOOLEAN", "warning": "BOOLEAN"}
