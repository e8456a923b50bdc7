"""Reading a drive log file as it is (CSV, Parquet or SUMO FCD XML; mapping and validation are separate), and the
checksums that identify a log's content."""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pandas as pd

from study.common.errors import UserError, check_choice, shown
from study.folder import logmap
from study.folder.drive_columns import COLUMNS

_CSV_TYPES = {"tl_id": "string", "segment": "string", "tl_state": "string", "controller": "string"}


# ---------------------------------------------------------------------------------------------- reading
def log_format(path: str | Path, fmt: str | None = None) -> str:
    """The format of a drive log file: `fmt` when given, else from the name (.csv/.csv.gz/.txt, .parquet/.pq,
    .xml/.xml.gz = SUMO FCD)."""
    if fmt is not None:
        return check_choice("format", fmt, logmap.FORMATS)
    name = Path(path).name.lower()
    if name.endswith((".parquet", ".pq")):
        return "parquet"
    if name.endswith((".csv", ".csv.gz", ".txt")):
        return "csv"
    if name.endswith((".xml", ".xml.gz")):
        return "sumo-fcd"
    raise UserError(f"{shown(path)}: unknown drive log format (use .csv, .parquet or SUMO FCD .xml, "
                    f"or --format)")


def read_drive_file(path: str | Path, fmt: str | None = None, vehicle: str | None = None) -> pd.DataFrame:
    """Read a CSV, Parquet or SUMO FCD drive log as it is (mapping and validation are separate)."""
    path = Path(path)
    if not path.exists():
        raise UserError(f"no such file: {path}")
    kind = log_format(path, fmt)
    try:
        if kind == "sumo-fcd":
            from study.logs.fcd import read_fcd

            return read_fcd(path, vehicle)
        if kind == "parquet":
            return pd.read_parquet(path)
        return pd.read_csv(path, dtype=_CSV_TYPES, low_memory=False)
    except UserError:
        raise
    except Exception as exc:  # unreadable file: one line
        raise UserError(f"cannot read {shown(path)}: {' '.join(str(exc).split())}") from exc


def file_checksum(path: str | Path) -> str:
    """sha256 (hex) of the file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def frame_checksum(df: pd.DataFrame) -> str:
    """sha256 (hex) of a canonical serialisation of a validated drive frame: for each known column in
    canonical order its name, then float64 little-endian bytes (numbers) or, for text and booleans, the
    distinct values in order of first appearance followed by each row's int64 code (-1 = missing)."""
    h = hashlib.sha256()
    for col in COLUMNS:
        if col not in df.columns:
            continue
        s = df[col]
        h.update(f"\x1e{col}\x1d".encode())
        if isinstance(s.dtype, pd.CategoricalDtype) or not pd.api.types.is_numeric_dtype(s) \
                or pd.api.types.is_bool_dtype(s):
            codes, uniques = pd.factorize(s.astype(object), use_na_sentinel=True)
            h.update("\x1f".join(str(u) for u in uniques).encode("utf-8") + b"\x1d")
            h.update(np.ascontiguousarray(codes.astype("<i8")).tobytes())
        else:
            h.update(np.ascontiguousarray(s.to_numpy(dtype="<f8", na_value=np.nan)).tobytes())
    return h.hexdigest()


