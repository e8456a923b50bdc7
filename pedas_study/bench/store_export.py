"""Time and peak memory of exports and imports of large drive data (`pedas-study bench export`).

Each operation runs in its own Python process (``python -m pedas_study.bench.store_export``), so that its peak
resident memory (``VmHWM`` of ``/proc/self/status`` on Linux, else ``resource.getrusage``) is its own and not the
bench's. Reported per operation: wall time (s) of the operation alone (after the imports and the opening of the
store), the process's peak RSS (MB), its growth during the operation (MB: peak after minus peak before, the imports
and the open store excluded), rows and bytes written or read.

* The store: the paper's study with ``samples`` synthetic drive samples (default 10 M = 10 participants x 2
  conditions x 500 000 samples), generated inside DuckDB from ``range()`` (no random draw: speed, position and
  traffic-light phase are smooth functions of the sample index and the drive; ``hud_arrow`` and ``warning`` are
  missing in baseline drives, as a simulator without a HUD logs them).
* Exports: ``export parquet``, ``export csv`` and ``export csv --deidentify`` of the whole store; the floor is
  DuckDB's own ``COPY drive_samples TO ... (FORMAT parquet)`` with DuckDB's default settings (its memory limit is 80 %
  of the machine's); the peer is what the export did before it streamed: the table fetched as one DataFrame
  (``ORDER BY drive_id, idx``) and written by ``DataFrame.to_parquet``.
* Import: ``drive import`` of a synthetic canonical CSV log of ``log_rows`` rows (default 5 M, about 200 MB:
  10 Hz, values rounded as a simulator writes them) into a fresh store; the floor is DuckDB reading the same file
  with ``read_csv`` straight into ``drive_samples`` (no validation, no computed columns).
"""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

SAMPLES = 10_000_000
LOG_ROWS = 5_000_000
PER_DRIVE = 500_000
#: the export and import targets (docs/store.md, "Drive logs")
TARGET_PARQUET_S = 10.0
TARGET_PARQUET_PEAK_MB = 1024.0
TARGET_IMPORT_GROWTH_MB = 300.0


@dataclass(frozen=True)
class Run:
    """One measured operation: `what` it was, wall `seconds`, peak RSS and its growth (MB), rows, bytes."""

    what: str
    seconds: float
    peak_mb: float
    growth_mb: float
    rows: int
    bytes: int


@dataclass(frozen=True)
class ExportBench:
    samples: int
    log_rows: int
    log_mb: float
    runs: tuple[Run, ...]

    def run(self, what: str) -> Run | None:
        return next((r for r in self.runs if r.what == what), None)

    def as_dict(self) -> dict:
        d = asdict(self)
        d["runs"] = {r.what: {k: v for k, v in asdict(r).items() if k != "what"} for r in self.runs}
        return d


# ---------------------------------------------------------------------------------------------- synthetic data
def samples_sql(n: int, per_drive: int = PER_DRIVE) -> str:
    """SELECT of `n` synthetic drive samples, `per_drive` per drive (drive_id 1, 2, ...) in the columns of
    ``drive_samples``; deterministic (no random draw)."""
    return f"""
    WITH base AS (
        SELECT i // {per_drive} + 1 AS drive_id, (i % {per_drive})::INTEGER AS idx,
               (i % {per_drive})::DOUBLE * 0.1 AS t, 8.0 + (i // {per_drive}) % 5 AS amp
        FROM range({int(n)}) r(i))
    SELECT drive_id, idx, t, amp * t - amp / 0.05 * (cos(0.05 * t) - 1.0) AS s,
           amp * (1.0 + sin(0.05 * t)) AS v,
           CASE WHEN idx < {per_drive // 2} THEN 'urban' ELSE 'highway' END AS segment,
           CASE WHEN idx < {per_drive // 2} THEN 50 / 3.6 ELSE 100 / 3.6 END AS speed_limit,
           amp * 0.05 * cos(0.05 * t) AS a,
           CASE WHEN idx % 500 < 400 THEN 'TL' || (idx // 500)::VARCHAR END AS tl_id,
           CASE WHEN (idx + drive_id * 37) % 900 < 400 THEN 'green'
                WHEN (idx + drive_id * 37) % 900 < 430 THEN 'yellow' ELSE 'red' END AS tl_state,
           CASE WHEN idx % 500 < 400 THEN (400 - idx % 500) * 0.5 END AS d_tl,
           CASE WHEN drive_id % 2 = 0 THEN 'rt' END AS controller,
           CASE WHEN drive_id % 2 = 0 THEN (idx % 3 - 1)::TINYINT END AS hud_arrow,
           CASE WHEN drive_id % 2 = 0 THEN idx % 97 = 0 END AS warning
    FROM base"""


def build_store(db: Path, samples: int, per_drive: int = PER_DRIVE) -> None:
    """A store of the paper's study holding `samples` synthetic samples in drives of `per_drive` samples."""
    from analysis.paper.published import PAPER_STUDY_DIR
    from study.store.store import Store
    from study.store.studies import definition, register

    n_drives = -(-samples // per_drive)
    with Store.open(db, actor="bench") as st:
        st.con.execute("SET enable_progress_bar = false")
        register(st, PAPER_STUDY_DIR)
        study = definition(st)
        conditions = study.condition_names
        with st.transaction():
            for k in range(-(-n_drives // len(conditions))):
                st.insert("participants", {"participant_id": f"P{k + 1:03d}", "protocol": study.protocol().name})
            for d in range(n_drives):
                n = min(per_drive, samples - d * per_drive)
                st.insert("drives", {"participant_id": f"P{d // len(conditions) + 1:03d}",
                                     "condition": conditions[d % len(conditions)], "source": "simulation",
                                     "route": "paper_route", "checksum": f"{d:064x}", "n_samples": n,
                                     "duration_s": (n - 1) * 0.1, "distance_m": 0.0, "seed": d,
                                     "meta": json.dumps({"energy_source": "simulated"})})
            st.con.execute(f"INSERT INTO drive_samples BY NAME {samples_sql(samples, per_drive)}")


def write_log(path: Path, rows: int) -> None:
    """A canonical drive log of `rows` samples at 10 Hz as CSV, written by DuckDB (the bench's own memory stays
    small): t s, s m, v m/s, segment, speed_limit m/s, tl_state, controller, hud_arrow, warning."""
    import duckdb

    sql = f"""
    SELECT round(i * 0.1, 1) AS t, round(12.0 * i * 0.1 - 12.0 / 0.05 * (cos(0.005 * i) - 1.0), 2) AS s,
           round(12.0 * (1.0 + sin(0.005 * i)), 3) AS v,
           CASE WHEN i < {rows // 2} THEN 'urban' ELSE 'highway' END AS segment,
           CASE WHEN i < {rows // 2} THEN 13.89 ELSE 33.33 END AS speed_limit,
           CASE WHEN i % 900 < 450 THEN 'green' ELSE 'red' END AS tl_state, 'rt' AS controller,
           i % 3 - 1 AS hud_arrow, i % 97 = 0 AS warning
    FROM range({int(rows)}) r(i)"""
    con = duckdb.connect()
    try:
        con.execute("SET enable_progress_bar = false")
        con.execute(f"COPY ({sql}) TO '{_sql_path(path)}' (FORMAT csv, HEADER true)")
    finally:
        con.close()


def _sql_path(path: Path) -> str:
    return str(path).replace("'", "''")


# ---------------------------------------------------------------------------------------------- one operation
def _maxrss_mb() -> float:
    """Peak resident memory of this process (MB): Linux's VmHWM of the process image; elsewhere ru_maxrss."""
    status = Path("/proc/self/status")
    if status.exists():
        # not ru_maxrss on Linux: it carries over the parent's peak through fork and exec
        for line in status.read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    import resource

    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kb / (1024.0 * 1024.0) if sys.platform == "darwin" else kb / 1024.0  # bytes on macOS, KiB elsewhere


def _size(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file()) if path.is_dir() else path.stat().st_size


def child(spec: dict) -> dict:
    """Run one operation of `spec` (op, db, out, ...) in this process and measure it."""
    import pandas  # noqa: F401  (imported before the baseline, as by every command)
    import pyarrow  # noqa: F401

    from study.store.store import Store

    op, db, out = spec["op"], Path(spec["db"]), Path(spec["out"])
    with Store.open(db, actor="bench") as st:
        if op == "export":
            from study.export.writer import export
        elif op == "import":
            from study.logs.importing import import_drive_file
            from study.store.studies import definition

            definition(st)  # parsed before the timing, as import_drive_file's own clock does
        before = _maxrss_mb()
        t0 = time.perf_counter()
        if op == "export":
            r = export(st, spec["fmt"], out, deidentify=spec.get("deidentify", False))
            rows = sum(r.files.values())
        elif op == "copy_floor":
            st.con.execute(f"COPY drive_samples TO '{_sql_path(out)}' (FORMAT parquet)")
            rows = int(st.one("SELECT count(*) FROM drive_samples"))
        elif op == "frame_peer":
            df = st.df("SELECT * FROM drive_samples ORDER BY drive_id, idx")
            df.to_parquet(out, index=False)
            rows = len(df)
        elif op == "import":
            rows = import_drive_file(st, "P001", "baseline", spec["log"]).n_samples
        elif op == "import_floor":
            with st.transaction():
                st.con.execute(
                    "INSERT INTO drive_samples (drive_id, idx, t, s, v, segment, speed_limit, tl_state, controller, "
                    "hud_arrow, warning) SELECT 1, row_number() OVER () - 1, t, s, v, segment, speed_limit, tl_state, "
                    "controller, hud_arrow, warning FROM read_csv(?)", [spec["log"]])
            rows = int(st.one("SELECT count(*) FROM drive_samples"))
        else:
            raise ValueError(f"unknown bench operation {op!r}")
        seconds = time.perf_counter() - t0
        peak = _maxrss_mb()
    written = out if out.exists() else Path(spec.get("log", out))
    return {"seconds": seconds, "peak_mb": peak, "growth_mb": peak - before, "rows": int(rows),
            "bytes": _size(written) if written.exists() else 0}


def measure(what: str, spec: dict) -> Run:
    """`spec` run by :func:`child` in a fresh Python process."""
    p = subprocess.run([sys.executable, "-m", "pedas_study.bench.store_export", json.dumps(spec)],
                       capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"bench operation {what} failed: {p.stderr.strip()[-2000:]}")
    r = json.loads(p.stdout.strip().splitlines()[-1])
    return Run(what, r["seconds"], r["peak_mb"], r["growth_mb"], r["rows"], r["bytes"])


def fresh_import_store(db: Path) -> None:
    """A store of the paper's study with participant P001 and no drive."""
    from analysis.paper.published import PAPER_STUDY_DIR
    from study.store.store import Store
    from study.store.studies import definition, register

    with Store.open(db, actor="bench") as st:
        register(st, PAPER_STUDY_DIR)
        st.insert("participants", {"participant_id": "P001", "protocol": definition(st).protocol().name})


def bench_export(samples: int = SAMPLES, log_rows: int = LOG_ROWS, peers: bool = True,
                 progress=None) -> ExportBench:
    """Build the store and the log in a temporary folder, then measure each operation in its own process."""
    say = progress or (lambda msg: None)
    runs = []
    with tempfile.TemporaryDirectory(prefix="pedas-bench-export-") as tmp:
        tmp = Path(tmp)
        db = tmp / "export.duckdb"
        say(f"building a store with {samples:,} drive samples")
        build_store(db, samples)
        plan = [("export parquet", {"op": "export", "fmt": "parquet"}),
                ("export csv", {"op": "export", "fmt": "csv"}),
                ("export csv --deidentify", {"op": "export", "fmt": "csv", "deidentify": True})]
        if peers:
            plan += [("floor: DuckDB COPY drive_samples to parquet", {"op": "copy_floor"}),
                     ("peer: drive_samples as one DataFrame to parquet", {"op": "frame_peer"})]
        for k, (what, spec) in enumerate(plan):
            say(what)
            out = tmp / f"out{k}"
            runs.append(measure(what, {**spec, "db": str(db), "out": str(out) + (
                ".parquet" if spec["op"] != "export" else "")}))
        log = tmp / "log.csv"
        say(f"writing a {log_rows:,}-row CSV log")
        write_log(log, log_rows)
        log_mb = log.stat().st_size / 1e6
        imports = [("drive import csv", "import")] + ([("floor: DuckDB read_csv into drive_samples",
                                                        "import_floor")] if peers else [])
        for k, (what, op) in enumerate(imports):
            say(what)
            idb = tmp / f"import{k}.duckdb"
            fresh_import_store(idb)
            runs.append(measure(what, {"op": op, "db": str(idb), "out": str(tmp / f"none{k}"), "log": str(log)}))
    return ExportBench(samples, log_rows, log_mb, tuple(runs))


def to_text(r: ExportBench) -> str:
    lines = [f"store of {r.samples:,} drive samples; log of {r.log_rows:,} rows ({r.log_mb:.0f} MB CSV); each "
             f"operation in its own process"]
    for x in r.runs:
        lines.append(f"{x.what:<50} {x.seconds:7.2f} s  peak RSS {x.peak_mb:7.0f} MB  growth {x.growth_mb:7.0f} MB"
                     f"  ({x.rows:,} rows, {x.bytes / 1e6:,.0f} MB)")
    p, i = r.run("export parquet"), r.run("drive import csv")
    goals = []
    if p is not None:
        goals.append(f"export parquet <= {TARGET_PARQUET_S:g} s and peak <= {TARGET_PARQUET_PEAK_MB:.0f} MB: "
                     f"{'met' if p.seconds <= TARGET_PARQUET_S and p.peak_mb <= TARGET_PARQUET_PEAK_MB else 'NOT met'}")
    if i is not None:
        goals.append(f"import growth <= {TARGET_IMPORT_GROWTH_MB:.0f} MB: "
                     f"{'met' if i.growth_mb <= TARGET_IMPORT_GROWTH_MB else 'NOT met'}")
    if goals:
        lines.append("goals: " + "; ".join(goals))
    return "\n".join(lines)


if __name__ == "__main__":  # one operation in a fresh process (see measure)
    print(json.dumps(child(json.loads(sys.argv[1]))))
