"""Replay of a participant's drives: one self-contained HTML page (no network, no build step) with a time slider,
play/pause, speed with advice and limit, leader gap, controller, the signal states on a space-time strip and the HUD
as the driver saw it; the person's drives side by side on one time axis.

The HUD of each sample is what the drive stored of it when it did: the HUD channels of
:data:`pedas.hud_log.HUD_CHANNELS` (a simulated pEDAS drive, a live session), read back with
:func:`pedas.hud_log.frame_from_channels` and the logged ``v_advice``, ``hud_arrow`` and ``hud_in_band``
(:func:`stored_frames`) — exactly what was shown. A drive without them (an older store, another simulator's log, a
baseline drive) has its HUD rebuilt from the drive log (docs/contracts.md columns) by :func:`log_frames`:

* digits, arrow direction and colour, band state and warning tone: the logged ``v``, ``hud_arrow``,
  ``hud_in_band``, ``warning``; the advised speed ``v_advice``; the limit ``speed_limit``;
* arrow length: min(|v_advice - v| / arrow_full_scale, 1), the rule of :func:`pedas.hud.advisory` whose plan[0]
  is the logged advice;
* traffic-light countdown and stop-sign icon: :func:`pedas.hud.advisory` with the route context when the drive was
  simulated on the study route (:class:`pedas.route.Route`: the signal program at SUMO time t + t_insert, the stop
  lines' positions). A drive log does not carry the controller's mode or the curve look-ahead, so
  the green-wave and curve icons are not replayed (docs/hud.md).

A drive without advice (baseline) shows its speed and limit only, as the driver saw no HUD advice. The page says
per drive which of the two it shows (:attr:`ReplayDrive.hud_source`).
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pedas.constants import KMH
from pedas.hud import HudContext, HudState, advisory
from pedas.hud_frame import HudFrame, display_kmh, hud_frame
from pedas.hud_log import HUD_CHANNELS, frame_from_channels, unfollowed_series
from pedas.params import CONTROLLER

SIGNAL_STATES = ("green", "yellow", "red")
HUD_NAMES = tuple(name for name, _, _ in HUD_CHANNELS)
#: what the page says about where a drive's HUD comes from (ReplayDrive.hud_source)
HUD_STORED = "stored"
HUD_REBUILT = "rebuilt"


@dataclass(frozen=True)
class ReplayDrive:
    """One drive of the page: condition, its samples (tidy frame: t, s, v, v_advice, speed_limit, leader_gap,
    controller, tl_id, tl_state, d_tl), the HUD frame of every sample and where the frames come from: ``stored``
    (the drive's HUD channels, :func:`stored_frames`), ``rebuilt`` (:func:`log_frames`) or, for a drive that stored
    them for some samples only, ``stored for K of N samples``."""

    condition: str
    samples: pd.DataFrame
    frames: pd.DataFrame
    hud_source: str = HUD_REBUILT


def log_frames(df: pd.DataFrame, route=None, t_insert: float | None = None,
               settings=CONTROLLER) -> pd.DataFrame:
    """The HUD frame (the fields of :class:`pedas.hud_frame.HudFrame`) of every sample of a drive log; see the
    module docstring.

    route: the :class:`pedas.route.Route` the drive was driven on (stop-sign icon) and t_insert (s) the SUMO time of
    its first sample (countdown, from the route's signal programs); without them neither is shown."""
    lights = {tl.tl_id: tl for tl in route.lights} if route is not None and t_insert is not None else {}
    stops = np.array(sorted(ss.s for ss in route.stops), float) if route is not None else np.empty(0)
    kw = {k: getattr(settings, k) for k in ("arrow_full_scale", "icon_range", "warn_delay", "standstill", "start_min")}
    cols = df[["t", "s", "v", "v_advice", "speed_limit", "tl_id", "d_tl", "hud_arrow", "hud_in_band", "warning",
               "tl_state"]]
    # the tone (a slow-down advice not followed) with the controller's timer over the logged t, v and arrow
    unfollowed = unfollowed_series(df["t"].to_numpy(float), df["v"].to_numpy(float),
                                   df["hud_arrow"].astype(object).where(df["hud_arrow"].notna(), None).tolist(),
                                   not_decel=settings.not_decel)
    frames = []
    for k, (t, s, v, adv, limit, tl_id, d_tl, arrow, in_band, warning, tl_state) in enumerate(
            cols.astype(object).itertuples(index=False)):
        limit = None if pd.isna(limit) else float(limit)
        if pd.isna(adv):   # no advice in this drive (baseline): speed and limit only
            frames.append(HudFrame(speed=display_kmh(max(v, 0.0)), advice=None, limit=display_kmh(limit), arrow=0,
                                   arrow_len=0.0, color="black", in_band=False, countdown=None, icon=None,
                                   warning=False))
            continue
        tl = lights.get(tl_id) if not pd.isna(tl_id) else None
        j = int(np.searchsorted(stops, s))
        ctx = HudContext(tl_distance=None if tl is None else float(d_tl),
                         tl_remaining=None if tl is None else tl.remaining(t + t_insert),
                         stop_distance=float(stops[j] - s) if j < stops.size else None, speed_limit=limit,
                         tl_state=None if pd.isna(tl_state) else str(tl_state))
        # countdown, its phase, icon and tone by the HUD's rules
        shown = advisory(HudState(v=float(v), slow_unfollowed=unfollowed[k]), [float(adv)], ctx, **kw)
        arrow = 0 if pd.isna(arrow) else int(arrow)                        # arrow, band, tone: as logged
        shown = dataclasses.replace(
            shown, hud_arrow=arrow, hud_in_band=bool(in_band) if not pd.isna(in_band) else arrow == 0,
            warning=bool(warning) if not pd.isna(warning) else False,
            arrow_len=0.0 if arrow == 0 else min(abs(float(adv) - v) / settings.arrow_full_scale, 1.0))
        frames.append(hud_frame(float(v), shown))
    return pd.DataFrame([f.as_dict() for f in frames], columns=list(HudFrame.__dataclass_fields__))


def stored_frames(df: pd.DataFrame) -> pd.DataFrame:
    """The HUD frame (the fields of :class:`pedas.hud_frame.HudFrame`) of every sample of a drive log that carries
    the HUD channels (:data:`HUD_NAMES`, every sample): :func:`pedas.hud_log.frame_from_channels` of the sample's
    channels with the advice as displayed (whole km/h of ``v_advice``), ``hud_arrow`` and ``hud_in_band``."""
    cols = df[list(HUD_NAMES) + ["v_advice", "hud_arrow", "hud_in_band"]].astype(object)
    frames = []
    for row in cols.itertuples(index=False):
        ch = {k: (float("nan") if pd.isna(x) else float(x)) for k, x in zip(HUD_NAMES, row)}
        adv, arrow, in_band = row[len(HUD_NAMES):]
        arrow = 0 if pd.isna(arrow) else int(arrow)
        frames.append(frame_from_channels(ch, None if pd.isna(adv) else display_kmh(float(adv)), arrow,
                                          arrow == 0 if pd.isna(in_band) else bool(in_band)))
    return pd.DataFrame([f.as_dict() for f in frames], columns=list(HudFrame.__dataclass_fields__))


def drive_frames(df: pd.DataFrame, route=None, t_insert: float | None = None) -> tuple[pd.DataFrame, str]:
    """(HUD frame of every sample, where they come from): the stored HUD channels where the log has them
    (``hud_speed`` not empty), :func:`log_frames` elsewhere; the source as :attr:`ReplayDrive.hud_source`."""
    have = (df["hud_speed"].notna().to_numpy() if all(c in df.columns for c in HUD_NAMES)
            else np.zeros(len(df), bool))
    if have.all():
        return stored_frames(df), HUD_STORED
    rebuilt = log_frames(df, route, t_insert)
    if not have.any():
        return rebuilt, HUD_REBUILT
    out = rebuilt.astype(object)
    out.loc[have] = stored_frames(df[have]).astype(object).to_numpy()
    return out, f"{HUD_STORED} for {int(have.sum())} of {len(df)} samples"


def _route_for(drive_row: dict):
    """The study route and t_insert of a drive simulated on it, else (None, None)."""
    from study.logs.simulated import ROUTE_NAME

    meta = json.loads(drive_row["meta"] or "{}")
    if drive_row["route"] != ROUTE_NAME or "t_insert" not in meta:
        return None, None
    from pedas.network import build_network
    from pedas.route_study import study_route

    return study_route(build_network()), float(meta["t_insert"])


def replay_drives(st, participant_id: str, condition: str, others: bool = True) -> list[ReplayDrive]:
    """The drive of `participant_id` in `condition` first, then (others=True) the person's other drives in
    alphabetical order of their conditions; UserError when the drive is not stored."""
    from study.logs.stored import drive_samples, list_channels
    from study.common.errors import UserError

    rows = st.df("SELECT condition, route, meta FROM drives WHERE participant_id = ? ORDER BY condition",
                 [participant_id]).to_dict("records")
    by_cond = {r["condition"]: r for r in rows}
    if condition not in by_cond:
        raise UserError(f"{participant_id} has no {condition} drive")
    order = [condition] + ([c for c in by_cond if c != condition] if others else [])
    # the HUD channels when this store has them (an older store has none: every HUD is rebuilt)
    hud = list(HUD_NAMES) if set(HUD_NAMES) <= set(list_channels(st)["channel"]) else False
    out = []
    for cond in order:
        df = drive_samples(st, participant_id, cond, channels=hud)
        stored = bool(hud) and bool(df["hud_speed"].notna().all())
        route, t_ins = (None, None) if stored else _route_for(by_cond[cond])   # the route only to rebuild
        frames, source = drive_frames(df, route, t_ins)
        out.append(ReplayDrive(cond, df[["t", "s", "v", "v_advice", "speed_limit", "leader_gap", "controller",
                                         "tl_id", "tl_state", "d_tl"]], frames, source))
    return out


def _num(a, digits: int) -> list:
    """Rounded floats for JSON, NaN -> null."""
    return [None if (x is None or x != x) else round(float(x), digits) for x in np.asarray(a, float)]


def _col(series: pd.Series) -> list:
    return [None if pd.isna(x) else (x.item() if hasattr(x, "item") else x) for x in series.astype(object)]


def _signals(d: ReplayDrive) -> list[dict]:
    """Per light the drive approached: its position (m, the stop line = s + d_tl) and the state intervals seen in
    the log [(t0, t1, state)], for the space-time strip."""
    df = d.samples
    dt = float(np.median(np.diff(df["t"].to_numpy(float)))) if len(df) > 1 else 0.0   # a sample lasts this long
    out = []
    for tl_id, g in df[df["tl_id"].notna()].groupby("tl_id", sort=False):
        t = g["t"].to_numpy(float)
        states = g["tl_state"].astype(str).to_numpy()
        cut = np.flatnonzero(states[1:] != states[:-1]) + 1
        starts = np.r_[0, cut]
        ends = np.r_[cut, t.size]
        spans = [[round(float(t[a]), 2), round(float(t[b - 1]) + dt, 2), str(states[a])] for a, b in zip(starts, ends)]
        pos = float(np.median(g["s"].to_numpy(float) + g["d_tl"].to_numpy(float)))
        out.append({"id": str(tl_id), "s": round(pos, 1), "spans": spans})
    return out


def page_data(participant_id: str, drives: list[ReplayDrive], theme: str = "light") -> dict:
    """The JSON the page embeds: per drive the sample columns (km/h for speeds), the HUD frames and signals."""
    out = []
    for d in drives:
        df, fr = d.samples, d.frames
        out.append({
            "condition": d.condition, "hud_source": d.hud_source,
            "t": _num(df["t"], 2), "s": _num(df["s"], 1), "v": _num(df["v"] / KMH, 2),
            "advice": _num(df["v_advice"] / KMH, 2), "limit": _num(df["speed_limit"] / KMH, 1),
            "gap": _num(df["leader_gap"], 1), "controller": _col(df["controller"]),
            "frames": {c: _col(fr[c]) for c in fr.columns},
            "signals": _signals(d),
        })
    return {"participant": participant_id, "drives": out, "theme": theme}


def replay_html(participant_id: str, drives: list[ReplayDrive], theme: str = "light") -> str:
    """The self-contained page (the HUD component in a theme of pedas.hud_theme, the page script and the data
    inline). Laid out for a 1400 x 900 screen: per drive a column at most 680 px wide, the HUD (360 px) with the
    timeline of what it showed right under it, so HUD and timeline share one screen for one or two drives."""
    import html

    from pedas.hud_png import WEB, hud_script

    payload = json.dumps(page_data(participant_id, drives, theme), separators=(",", ":"), sort_keys=True)
    payload = payload.replace("<", "\\u003c")   # the JSON sits inside a <script> element: no "</script>", "<!--"
    names = {"pedas": "pEDAS"}
    title = html.escape(f"Replay of {participant_id}: " + " | ".join(names.get(d.condition, d.condition) for d in drives))
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<meta name="viewport" content="width=device-width, initial-scale=1">
<style>
body{{font-family:DejaVu Sans,Arial,sans-serif;margin:0 12px;}}
header{{position:sticky;top:0;background:#fff;padding:8px 0;border-bottom:1px solid #ccc;display:flex;gap:10px;
align-items:center;z-index:1}}
#slider{{flex:1}}
#drives{{display:grid;grid-template-columns:repeat({len(drives)},minmax(0,680px));gap:18px}}
pedas-hud{{width:min(100%,360px)}}
.readout{{font-size:13px;min-height:2.6em;margin:4px 0}}
.hud-source{{font-size:12px;color:#555;margin:0 0 6px}}
h2{{margin:6px 0;font-size:20px}}
.legend{{font-size:12px;margin:0 0 8px;display:flex;flex-wrap:wrap;gap:4px 12px}}
.legend i{{display:inline-block;width:14px;height:10px;margin-right:4px;vertical-align:middle}}
.legend i.line,.legend i.dash{{height:0;border-top:2px solid}}.legend i.dash{{border-top-style:dashed}}
</style>
<script>{hud_script()}</script></head>
<body>
<header><strong>{html.escape(participant_id)}</strong><button id="play" type="button">Play</button>
<label>speed <select id="rate"><option value="1">1x</option><option value="5" selected>5x</option>
<option value="20">20x</option></select></label>
<input id="slider" type="range" min="0" max="1" step="0.2" value="0" aria-label="time">
<span id="clock">t = 0.0 s</span></header>
<div id="drives"></div>
<script type="application/json" id="replay-data">{payload}</script>
<script>{(WEB / "replay.js").read_text(encoding="utf-8")}</script>
</body></html>
"""


def write_replay(st, participant_id: str, condition: str, out: str | Path, others: bool = True,
                 theme: str = "light") -> Path:
    """Write the replay page of a participant's drive (and, with others=True, the person's other drives beside
    it) to `out` with the HUD in `theme`; the path."""
    out = Path(out)
    text = replay_html(participant_id, replay_drives(st, participant_id, condition, others), theme)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text, encoding="utf-8")
    return out


def serve_file(path: Path, host: str = "127.0.0.1", port: int = 8018) -> None:
    """Serve this one page (and nothing else of its folder) at http://host:port/ until interrupted (Ctrl-C)."""
    from http.server import BaseHTTPRequestHandler, HTTPServer

    body = Path(path).read_bytes()

    class Handler(BaseHTTPRequestHandler):
        timeout = 10  # s: a client that connects and sends nothing does not hold the server

        def do_GET(self):  # noqa: N802 (http.server's name)
            if self.path not in ("/", "/" + Path(path).name):
                self.send_error(404)
                return
            self.send_response(200)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args) -> None:  # quiet
            pass

    # one thread: with request threads running Python code, CPython 3.11 can lose a Ctrl-C that lands in another
    # thread (the signal stays pending until the next one; observed: a server alive 30 s after SIGINT)
    srv = HTTPServer((host, port), Handler)
    print(f"serving http://{host}:{srv.server_address[1]}/ (Ctrl-C stops)", flush=True)
    try:
        srv.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        srv.server_close()
