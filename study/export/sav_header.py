"""The creation date and time in an SPSS .sav file's header, set to a fixed value.

pyreadstat (ReadStat) stamps every .sav it writes with the clock of the moment (the file header's
``creation_date`` "dd mmm yy" and ``creation_time`` "hh:mm:ss") and has no option to leave it out. In a
de-identified export that stamp says when the export was made — a date that can tie the file to a study day — so
it is overwritten with :data:`FIXED` (01 Jan 70 00:00:00), which also makes the file byte-identical for an unchanged
store.

Header layout (IBM SPSS Statistics, "System File Format", record type 1): rec_type[4], prod_name[60],
layout_code, nominal_case_size, compression, weight_index, ncases (int32 each), bias (float64),
creation_date[9] at byte 92, creation_time[8] at byte 101, file_label[64], padding[3]. The header is never
compressed (.sav and .zsav alike).
"""
from __future__ import annotations

from pathlib import Path

DATE_AT, TIME_AT = 92, 101
FIXED = b"01 Jan 70" + b"00:00:00"


def clear_timestamp(path: str | Path) -> None:
    """Overwrite the creation date and time of the .sav file at `path` with :data:`FIXED` (in place)."""
    with open(path, "r+b") as f:
        if f.read(4) not in (b"$FL2", b"$FL3"):
            raise ValueError(f"{path} is not an SPSS system file")
        f.seek(DATE_AT)
        f.write(FIXED)
