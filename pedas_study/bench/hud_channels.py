"""What storing the HUD channels costs (``pedas-study bench hud [--copies N] [--json]``).

One simulated pEDAS drive of the reference cohort (P003, from the drive cache; simulated once when not cached) is
imported with :func:`study.logs.importing.import_drive_frame` into two fresh stores of the paper's study, `copies` times
each (under as many participants): once with its seven HUD channels (:data:`pedas.drive.HUD_LOG_COLUMNS`), once
without. Reported: the median import time per drive of each, and the store's growth per drive — the DuckDB file
after CHECKPOINT minus the same store before the imports, divided by `copies`, so that DuckDB's 256 KiB blocks
average out — against the raw size of the seven channels (8 bytes per value and sample).
"""
from __future__ import annotations

import statistics
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path


@dataclass(frozen=True)
class HudChannelsBench:
    samples: int               # samples of the drive
    copies: int                # drives imported into each store
    import_s_without: float    # median import time per drive, without the HUD channels (s)
    import_s_with: float       # ... with them (s)
    bytes_per_drive_without: float   # store growth per drive (bytes)
    bytes_per_drive_with: float
    raw_channel_bytes: int     # 7 channels x 8 bytes x samples

    def as_dict(self) -> dict:
        return asdict(self)

    def to_text(self) -> str:
        dt = self.import_s_with - self.import_s_without
        db = self.bytes_per_drive_with - self.bytes_per_drive_without
        return (f"one pEDAS drive ({self.samples} samples), {self.copies} imports per store: import "
                f"{self.import_s_without * 1e3:.0f} ms without the HUD channels, {self.import_s_with * 1e3:.0f} ms "
                f"with them (+{dt * 1e3:.0f} ms, +{dt / self.import_s_without:.0%}); store "
                f"{self.bytes_per_drive_without / 1024:.0f} KiB per drive without, "
                f"{self.bytes_per_drive_with / 1024:.0f} KiB with (+{db / 1024:.0f} KiB, "
                f"+{db / self.bytes_per_drive_without:.0%}; the channels' raw size {self.raw_channel_bytes / 1024:.0f} "
                f"KiB)")


def reference_drive(participant: str = "P003"):
    """The simulated pEDAS drive of a participant of the reference cohort (the drive cache, else simulated)."""
    import pandas as pd

    from pedas.cohort import cohort_tasks, run_task
    from pedas.paths import REPO_ROOT

    people = pd.read_csv(REPO_ROOT / "data" / "reference" / "participants.csv")
    task = [t for t in cohort_tasks(people[people["participant_id"] == participant][["participant_id", "style"]])
            if t.condition == "pedas"][0]
    return task, run_task(task)


def _store_with_drives(db: Path, df, copies: int, task) -> tuple[list[float], int, int]:
    """(import times, file size before the imports, after them) of `copies` imports of `df` into a fresh store."""
    from pedas_study.bench.store_export import fresh_import_store
    from study.logs.importing import import_drive_frame
    from study.logs.simulated import ROUTE_NAME
    from study.store.store import Store
    from study.store.studies import definition

    fresh_import_store(db)
    with Store.open(db, actor="bench") as st:
        protocol = definition(st).protocol().name
        for i in range(2, copies + 1):
            st.insert("participants", {"participant_id": f"P{i:03d}", "protocol": protocol})
        st.con.execute("CHECKPOINT")
    before = db.stat().st_size
    times = []
    with Store.open(db, actor="bench") as st:
        definition(st)   # parsed before the clock starts
        for i in range(1, copies + 1):
            t0 = time.perf_counter()
            import_drive_frame(st, f"P{i:03d}", "pedas", df, source="simulation", route=ROUTE_NAME, seed=task.seed)
            times.append(time.perf_counter() - t0)
        st.con.execute("CHECKPOINT")
    return times, before, db.stat().st_size


def bench_hud_channels(copies: int = 10) -> HudChannelsBench:
    from pedas.drive import HUD_LOG_COLUMNS

    task, df = reference_drive()
    if not set(HUD_LOG_COLUMNS) <= set(df.columns):
        raise RuntimeError("the cached drive has no HUD channels")
    plain = df.drop(columns=list(HUD_LOG_COLUMNS))
    with tempfile.TemporaryDirectory(prefix="pedas-bench-hud-") as tmp:
        t_without, b0, b1 = _store_with_drives(Path(tmp) / "without.duckdb", plain, copies, task)
        t_with, c0, c1 = _store_with_drives(Path(tmp) / "with.duckdb", df, copies, task)
    return HudChannelsBench(len(df), copies, statistics.median(t_without), statistics.median(t_with),
                            (b1 - b0) / copies, (c1 - c0) / copies, 8 * len(HUD_LOG_COLUMNS) * len(df))
