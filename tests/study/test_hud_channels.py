"""The HUD channels in the store (study.logs.hud_channels, study.logs.importing.import_drive_frame): a drive log that carries
what the HUD showed keeps it as extra channels with the documented units, its canonical columns stored as without
them; its checksum counts them; bad values are one-line errors that leave the store unchanged."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pedas.hud_log import HUD_CHANNELS
from tests.e2e.test_replay import log

NAMES = [name for name, _, _ in HUD_CHANNELS]


def hud_log(n: int = 50) -> pd.DataFrame:
    """:func:`tests.e2e.test_replay.log` (36 km/h, limit 50, the light L1 ahead until s = 300 m) with the HUD channels:
    speed 36 and limit 50; arrow half length while the arrow points up (first half), none after; a green
    countdown 9, 8, ... in the first 10 samples; the green-wave icon at samples 0-19, the curve icon at 30-39;
    the tone at samples 40-44."""
    df = log(n)
    k = np.arange(n)
    df["hud_speed"] = 36.0
    df["hud_limit"] = 50.0
    df["hud_arrow_len"] = np.where(k < n // 2, 0.5, 0.0)
    df["hud_countdown"] = np.where(k < 10, 9.0 - k, np.nan)
    df["hud_light"] = np.where(k < 10, 1.0, np.nan)
    df["hud_icon"] = np.select([k < 20, (k >= 30) & (k < 40)], [1.0, 4.0], 0.0)
    df["hud_tone"] = ((k >= 40) & (k < 45)).astype(float)
    df["hud_arrow_shown"] = np.where(k < n // 2, 1.0, 0.0)
    return df


def _store(db):
    from study.store.store import Store

    return Store.open(db, actor="lab")


def _add(st, *ids):
    from study.people.participants import add_participant

    for pid in ids:
        add_participant(st, pid)


def test_import_keeps_the_hud_channels_with_their_units(paper_db):
    from study.logs.stored import drive_samples, list_channels
    from study.logs.importing import import_drive_frame

    with _store(paper_db) as st:
        _add(st, "P001", "P002")
        r = import_drive_frame(st, "P001", "pedas", hud_log(), source="import")
        plain = import_drive_frame(st, "P002", "pedas", log(), source="import")
        assert r.status == "imported" and r.channels == tuple(NAMES) and r.ignored_columns == ()
        assert plain.channels == ()
        _add(st, "P003")   # a log written before the shown arrow was kept: imported with the others
        older = import_drive_frame(st, "P003", "pedas", hud_log().drop(columns="hud_arrow_shown"), source="import")
        assert older.status == "imported" and older.channels == tuple(n for n in NAMES if n != "hud_arrow_shown")
        ch = list_channels(st).set_index("channel")
        assert ch.loc[NAMES, "unit"].tolist() == [unit for _, unit, _ in HUD_CHANNELS]
        assert ch.loc["hud_icon", "description"].startswith("icon shown: 0 none, 1 green wave")
        got = drive_samples(st, "P001", "pedas", channels=NAMES)
        other = drive_samples(st, "P002", "pedas", channels=NAMES)
    want = hud_log()
    # the channels as given (NaN stored as NULL, read back as NaN) ...
    pd.testing.assert_frame_equal(got[NAMES], want[NAMES], check_dtype=False)
    # ... the canonical columns exactly as the same log stored without them; the other drive has no HUD values
    canonical = [c for c in got.columns if c not in NAMES]
    assert got[canonical].equals(other[canonical])
    assert other[NAMES].isna().all().all()


def test_checksum_counts_the_channels(paper_db):
    from study.logs.reading import frame_checksum
    from study.logs.importing import import_drive_frame
    from study.logs.validation import validate_drive
    from study.common.errors import UserError

    with _store(paper_db) as st:
        _add(st, "P001", "P002")
        plain = import_drive_frame(st, "P002", "pedas", log(), source="import")
        r = import_drive_frame(st, "P001", "pedas", hud_log(), source="import")
        # a log without HUD channels keeps the checksum it always had; the same log with them is other content
        assert plain.checksum == frame_checksum(validate_drive(log())[0])
        assert r.checksum != plain.checksum
        assert import_drive_frame(st, "P001", "pedas", hud_log(), source="import").status == "unchanged"
        changed = hud_log()
        changed.loc[7, "hud_tone"] = 1.0
        with pytest.raises(UserError, match="already has a pedas drive .* different content"):
            import_drive_frame(st, "P001", "pedas", changed, source="import")
        again = import_drive_frame(st, "P001", "pedas", changed, source="import", replace=True)
        assert again.status == "replaced" and again.checksum not in (r.checksum, plain.checksum)


def _bad(df, col, row, value):
    df = df.astype({col: object}) if isinstance(value, str) else df
    df.loc[row - 1, col] = value
    return df


@pytest.mark.parametrize(("change", "message"), [
    (lambda d: _bad(d, "hud_icon", 5, 7.0), "column hud_icon row 5: 7 is not one of 0|1|2|3|4"),
    (lambda d: _bad(d, "hud_light", 3, 0.0), "column hud_light row 3: 0 is not one of 1|2|3"),
    (lambda d: _bad(d, "hud_tone", 12, 0.5), "column hud_tone row 12: 0.5 is not one of 0|1"),
    (lambda d: _bad(d, "hud_countdown", 2, 8.5), "column hud_countdown row 2: 8.5 is outside 0..9 s or not whole"),
    (lambda d: _bad(d, "hud_countdown", 2, 10.0), "column hud_countdown row 2: 10 is outside 0..9 s or not whole"),
    (lambda d: _bad(d, "hud_arrow_len", 9, 1.5), "column hud_arrow_len row 9: 1.5 is outside 0..1 1"),
    (lambda d: _bad(d, "hud_speed", 4, np.inf), "column hud_speed row 4: inf is outside 0..252 km/h"),
    (lambda d: _bad(d, "hud_limit", 6, "fast"), "column hud_limit row 6: 'fast' is not a number"),
    (lambda d: d.drop(columns=["hud_tone", "hud_light"]), "the log has HUD channels but not hud_light, hud_tone"),
])
def test_bad_hud_values_are_one_line_and_leave_the_store_unchanged(paper_db, change, message):
    from study.logs.importing import import_drive_frame
    from study.logs.stored import list_channels
    from study.common.errors import UserError

    with _store(paper_db) as st:
        _add(st, "P001")
        with pytest.raises(UserError) as exc:
            import_drive_frame(st, "P001", "pedas", change(hud_log()), source="import")
        assert str(exc.value).startswith(message) and "\n" not in str(exc.value)
        assert st.one("SELECT count(*) FROM drives") == 0 and len(list_channels(st)) == 0
        assert "hud_speed" not in st.df("SELECT * FROM drive_samples LIMIT 0").columns


def test_a_canonical_problem_comes_before_the_hud_channels(paper_db):
    """The drive-log format's checks run first: a log with a bad speed and a bad HUD code reports the speed."""
    from study.logs.importing import import_drive_frame
    from study.common.errors import UserError

    df = _bad(hud_log(), "hud_icon", 5, 7.0)
    df.loc[2, "v"] = -1.0
    with _store(paper_db) as st:
        _add(st, "P001")
        with pytest.raises(UserError, match=r"^column v row 3: speed -1 m/s outside"):
            import_drive_frame(st, "P001", "pedas", df, source="import")


def test_channels_cli_lists_them(cli, paper_db):
    from study.logs.importing import import_drive_frame

    with _store(paper_db) as st:
        _add(st, "P001")
        import_drive_frame(st, "P001", "pedas", hud_log(), source="import")
    r = cli("drive", "channels", db=paper_db)
    assert r.code == 0
    for name, unit, _ in HUD_CHANNELS:
        assert any(line.split()[:2] == [name, unit] for line in r.out.splitlines()), (name, r.out)


def test_a_live_log_stores_the_hud_channels_it_is_given(paper_db):
    """Rows with the HUD channels (what a live server sends with each advice) are stored at every flush, marked
    incomplete, and kept by the complete log that replaces the partial one on close."""
    from study.logs.stored import drive_samples, list_channels
    from study.logs.live_log import LIVE_COLUMNS, LiveDriveLog

    df = hud_log(60).assign(a=0.0, grade=0.0)
    rows = df[list(LIVE_COLUMNS) + NAMES].astype(object).where(df.notna(), None).to_dict("records")
    with _store(paper_db) as st:
        _add(st, "P001")
        lg = LiveDriveLog(st, "P001", "pedas", None)
        for r in rows[:25]:
            lg.append(r)
        assert lg.flush() == 25
        assert list_channels(st)["channel"].tolist() == sorted(NAMES)
        part = drive_samples(st, "P001", "pedas", channels=NAMES)
        assert len(part) == 25 and part.loc[0, "hud_icon"] == 1.0 and part.loc[9, "hud_countdown"] == 0.0
        for r in rows[25:]:
            lg.append(r)
        result = lg.close()
        assert result.channels == tuple(NAMES) and result.status == "replaced"
        got = drive_samples(st, "P001", "pedas", channels=NAMES)
    pd.testing.assert_frame_equal(got[NAMES], df[NAMES], check_dtype=False)


def test_a_live_log_without_hud_channels_stays_as_it_was(paper_db):
    from study.logs.stored import list_channels
    from study.logs.live_log import LIVE_COLUMNS, LiveDriveLog

    df = log(20).assign(a=0.0, grade=0.0)
    with _store(paper_db) as st:
        _add(st, "P001")
        lg = LiveDriveLog(st, "P001", "pedas", None)
        for r in df[list(LIVE_COLUMNS)].astype(object).where(df.notna(), None).to_dict("records"):
            lg.append(r)
        assert lg.close().channels == ()
        assert len(list_channels(st)) == 0
