"""Time of the shipped standard driving measures (`pedas-study bench measures`) against the built-in KPIs' pass, in one
process, on the KPI bench's synthetic ``drive_samples`` table (:func:`pedas_study.bench.kpi.synthetic_sql`, default
10 M rows = 1 000 drives x 10 000 samples at 10 Hz) with the channels the measures read added: a steering wheel angle
(deg: a 0.2 Hz sine of 6 deg plus noise), a lead vehicle 20-45 m ahead at a slowly varying speed, a takeover request
at t = 300 s, the brake pedal pressed 1.2 s after it and the accelerator released 0.6 s after it.

Timed: the built-in KPI pass (:func:`analysis.drives.kpis.kpis_from_relation`, every built-in group) and every shipped
measure with its default options, per drive and per segment (:func:`analysis.drives.measures.measure_kpis`), medians
of ``repeat`` runs, and their ratio (target <= 3).
"""
from __future__ import annotations

import statistics
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from study.folder.kpi_spec import MeasureKpi
from study.folder.measure_library import MEASURES

ROWS = 10_000_000
TARGET_RATIO = 3.0


def bench_measures_decl() -> tuple[MeasureKpi, ...]:
    """Every shipped measure with its defaults (the event ones on the takeover request), per segment."""
    out = []
    for name, m in MEASURES.items():
        opts = {**m.defaults(), **{o.name: "tor" for o in m.options if o.kind == "channel"}}
        out.append(MeasureKpi(name, name, tuple(sorted(opts.items())), per_segment=True, unit=m.unit_of(opts)))
    return tuple(out)


def synthetic_measures_sql(n_rows: int, samples_per_drive: int, seed: int) -> str:
    """The KPI bench's synthetic samples with the measures' channels (module docstring); deterministic in ``seed``."""
    from pedas_study.bench.kpi import synthetic_sql

    def u(salt: int) -> str:   # uniform in [0, 1) per sample from the seeded hash
        return f"((hash(drive_id, idx, {int(seed)}, {salt}) % 1000003)::DOUBLE / 1000003.0)"

    return f"""
    SELECT *,
           (6.0 * sin(1.2566 * t + drive_id) + 0.4 * ({u(11)} - 0.5))::DOUBLE AS steering_angle,
           (32.5 + 12.5 * sin(0.02 * t + drive_id))::DOUBLE AS leader_gap,
           (v + 0.25 * cos(0.02 * t + drive_id))::DOUBLE AS leader_v,
           (t >= 300 AND t < 305)::INTEGER::DOUBLE AS tor,
           CASE WHEN t >= 301.2 AND t < 310 THEN 60.0 ELSE 0.0 END AS brake_pedal,
           CASE WHEN t >= 300.6 AND t < 312 THEN 0.0 ELSE 20.0 END AS accel_pedal
    FROM ({synthetic_sql(n_rows, samples_per_drive, seed)})
    """


@dataclass
class MeasuresBench:
    rows: int
    drives: int
    measures: int
    repeat: int
    builtin_s: float
    measures_s: float
    builtin_runs: list = field(default_factory=list)
    measures_runs: list = field(default_factory=list)

    @property
    def ratio(self) -> float:
        return self.measures_s / self.builtin_s

    def as_dict(self) -> dict:
        return {**asdict(self), "ratio": self.ratio, "target_ratio": TARGET_RATIO,
                "meets_target": self.ratio <= TARGET_RATIO}

    def text(self) -> str:
        return "\n".join([
            f"bench measures: {self.rows:,} samples ({self.drives:,} drives), median of {self.repeat}",
            f"  built-in KPIs (every group, per segment)         : {self.builtin_s:8.2f} s",
            f"  {self.measures} shipped measures (defaults, per segment): {self.measures_s:8.2f} s",
            f"  ratio measures / built-ins: {self.ratio:.2f} (target <= {TARGET_RATIO:g}: "
            f"{'met' if self.ratio <= TARGET_RATIO else 'NOT met'})"])


def run_bench(rows: int = ROWS, repeat: int = 3, seed: int = 1, samples_per_drive: int = 10_000,
              threads: int | None = None) -> MeasuresBench:
    """Generate the table in a temporary DuckDB file and time both passes (module docstring)."""
    import duckdb

    from analysis.drives.kpis import kpis_from_relation
    from analysis.drives.measures import measure_kpis

    n_per = min(int(samples_per_drive), int(rows))
    n_drives = max(1, rows // n_per)
    rows = n_drives * n_per
    decl = bench_measures_decl()
    with tempfile.TemporaryDirectory(prefix="measures-bench-") as tmp:
        con = duckdb.connect(str(Path(tmp) / "bench.duckdb"))
        try:
            con.execute("SET enable_progress_bar = false")
            if threads:
                con.execute(f"SET threads = {int(threads)}")
            nthreads = int(con.execute("SELECT current_setting('threads')").fetchone()[0])
            con.execute("CREATE TABLE drive_samples AS " + synthetic_measures_sql(rows, n_per, seed))
            con.execute("CHECKPOINT")
            builtin_runs, measure_runs = [], []
            for _ in range(max(1, repeat)):
                t0 = time.perf_counter()
                kpis_from_relation(con, "drive_samples", workers=nthreads)
                builtin_runs.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                seg, _ = measure_kpis(con, "drive_samples", decl, ordered=True)
                measure_runs.append(time.perf_counter() - t0)
                if seg[[k.name for k in decl]].isna().all().any():
                    raise RuntimeError("a measure gave no value on any drive of the synthetic table")
        finally:
            con.close()
    return MeasuresBench(rows, n_drives, len(decl), max(1, repeat), statistics.median(builtin_runs),
                         statistics.median(measure_runs), builtin_runs, measure_runs)
