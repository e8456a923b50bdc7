"""The shipped standard driving measures (:mod:`study.folder.measure_library`, docs/measures.md), computed per drive,
per route segment and per region of interest.

The samples stream out of DuckDB in drive order as Arrow record batches (a batch's last, possibly incomplete drive
waits for the next batch); each drive's channels become numpy arrays once, and every measure works on whole arrays
(filters and resampling with scipy), so nothing loops over samples in Python. The one loop is the reversal count of
the steering reversal rate, over the filtered signal's stationary points (Markkula & Engstrom 2006 count them
greedily; they are a small share of the samples).

Conventions shared with the built-in KPIs (:mod:`analysis.drives.kpis`): the interval ``i`` runs from sample ``i`` to
``i+1`` of the drive and belongs to the window of sample ``i`` (left point); a window (a segment, a region) is the
set of its samples; a statistic with no sample to work on is NULL (NaN), never 0.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pandas as pd

#: channels every drive carries to the measures besides the declared ones
_BASE = ("t", "s", "v", "a", "speed_limit")
_BATCH_ROWS = 1 << 20


# ------------------------------------------------------------------------------------------- the measures
def _finite(x: np.ndarray) -> np.ndarray:
    return x[np.isfinite(x)]


def _mean(x) -> float:
    x = _finite(x)
    return float(x.mean()) if len(x) else math.nan


def _sd(x) -> float:
    """Sample standard deviation (n - 1), as J2944 asks; NaN below two samples."""
    x = _finite(x)
    return float(x.std(ddof=1)) if len(x) > 1 else math.nan


def speed_mean(d, sel, o):
    return _mean(d["v"][sel])


def speed_sd(d, sel, o):
    return _sd(d["v"][sel])


def speed_exceedance(d, sel, o):
    over = d["v"][sel] > d["speed_limit"][sel] + o["tolerance_kmh"] / 3.6
    dt, ds = d["dt"][sel], d["ds"][sel]
    if o["statistic"] == "distance_m":
        return float(ds[over].sum())
    time = float(dt[over].sum())
    if o["statistic"] == "share":
        total = dt.sum()
        return time / total if total > 0 else math.nan
    return time


def sdlp(d, sel, o):
    return _sd(d["lat_pos"][sel])


def lateral_position_mean(d, sel, o):
    return _mean(d["lat_pos"][sel])


def _runs(flag: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(start, end) indices of the runs of True in `flag`; `end` is the first index after the run."""
    edges = np.diff(np.concatenate(([0], flag.astype(np.int8), [0])))
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)


def lane_departure(d, sel, o):
    lat, t, dt = d["lat_pos"][sel], d["t"][sel], d["dt"][sel]
    out = np.abs(lat) + o["vehicle_width_m"] / 2 > o["lane_width_m"] / 2     # NaN compares False
    start, end = _runs(out)
    t_end = np.append(t, t[-1] + dt[-1])          # the window's end: its last sample's interval
    dur = t_end[end] - t[start]
    dur = dur[dur >= o["min_duration_s"]]
    if o["statistic"] == "count":
        return float(len(dur))
    if o["statistic"] == "duration_total_s":
        return float(dur.sum())
    return float(dur.mean()) if len(dur) else math.nan


_HEADWAY_ADD = {"A": "lead_length_m", "B": "subject_length_m", "C": None}


def headways(gap, v, o) -> np.ndarray:
    """Time headway (s) of option A/B/C from the gap (m) and the subject's speed (m/s); NaN without a lead vehicle,
    at (near) standstill, or above ``max_s`` (not car following)."""
    add = _HEADWAY_ADD[o["option"]]
    dist = gap + (o[add] if add else 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        thw = np.where(v > 0.1, dist / v, np.nan)
    return np.where(thw <= o["max_s"], thw, np.nan)


def time_headway(d, sel, o):
    thw = headways(d["leader_gap"][sel], d["v"][sel], o)
    ok = np.isfinite(thw)
    if not ok.any():
        return math.nan
    if o["statistic"] == "min":
        return float(thw[ok].min())
    if o["statistic"] == "mean":
        return float(thw[ok].mean())
    dt = d["dt"][sel]
    total = dt[ok].sum()
    return float(dt[ok & (thw < o["threshold_s"])].sum() / total) if total > 0 else math.nan


def distance_gap(d, sel, o):
    g = _finite(d["leader_gap"][sel])
    if not len(g):
        return math.nan
    return float(g.min() if o["statistic"] == "min" else g.mean())


def ttc(d, sel, o):
    gap, closing = d["leader_gap"][sel], d["v"][sel] - d["leader_v"][sel]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where(closing > 0, gap / closing, np.nan)
    ok = np.isfinite(x)
    if o["statistic"] == "min":
        return float(x[ok].min()) if ok.any() else math.nan
    if not np.isfinite(gap).any():
        return math.nan                          # no lead vehicle logged: not 0 s
    return float(d["dt"][sel][ok & (x < o["threshold_s"])].sum())


def _cached(d, key, make):
    """A drive-level derived signal, made once per drive and shared by its windows."""
    cache = d.setdefault("_cache", {})
    if key not in cache:
        cache[key] = make()
    return cache[key]


def _onsets(flag: np.ndarray) -> np.ndarray:
    """Indices of the rising edges of a 0/1 channel (NaN = 0); the drive's first sample is none (its onset was not
    logged)."""
    on = np.nan_to_num(flag) > 0.5
    return np.flatnonzero(on[1:] & ~on[:-1]) + 1


def _event_onsets(d, sel, event: str) -> np.ndarray:
    """Indices of the rising edges of the 0/1 channel `event` in the window `sel` (the drive's onsets found once)."""
    onsets = _cached(d, ("onsets", event), lambda: _onsets(d[event]))
    return onsets[_mask(sel, len(d["t"]))[onsets]]


def _responses(d, onsets: np.ndarray, channel: str, thr: float, below: bool) -> np.ndarray:
    """Index of the first sample at or after each onset where `channel` is at or above the threshold `thr`
    (``below``: at or below it), -1 where none follows; the drive's samples over the threshold are found once."""
    x = d[channel]
    hits = _cached(d, ("responses", channel, thr, below), lambda: np.flatnonzero(x <= thr if below else x >= thr))
    k = np.searchsorted(hits, onsets)
    out = np.full(len(onsets), -1, dtype=np.int64)
    found = k < len(hits)
    out[found] = hits[k[found]]
    return out


def _per_event(x: np.ndarray, statistic: str) -> float:
    """The window's value of a per-event time (NaN: none): the first event's (``first``) or the mean of the events
    that have one (``mean``)."""
    if statistic == "first":
        return float(x[0])
    return float(np.nanmean(x)) if np.isfinite(x).any() else math.nan


def _reaction(d, sel, o, channel: str, below: bool):
    """Time (s) from each event onset in the window to the first sample at or after it where `channel` is at or
    above (``below``: at or below) the threshold; NaN where none follows within ``max_s``."""
    onsets = _event_onsets(d, sel, o["event"])
    if not len(onsets):
        return math.nan
    hit = _responses(d, onsets, channel, o["threshold_pct"], below)
    t = d["t"]
    rt = np.where(hit >= 0, t[hit] - t[onsets], np.nan)
    rt[rt > o["max_s"]] = np.nan
    return _per_event(rt, o["statistic"])


def _mask(sel, n: int) -> np.ndarray:
    if isinstance(sel, np.ndarray) and sel.dtype == bool:
        return sel
    m = np.zeros(n, bool)
    m[sel] = True
    return m


def brake_reaction_time(d, sel, o):
    return _reaction(d, sel, o, "brake_pedal", below=False)


def accelerator_release_time(d, sel, o):
    return _reaction(d, sel, o, "accel_pedal", below=True)


def accelerator_to_brake_time(d, sel, o):
    """Accelerator-to-brake transition time (s) of each event onset in the window: t_brake - t_release, where
    t_release is the first sample at or after the onset with the accelerator pedal at or below
    ``accel_threshold_pct`` and t_brake the first sample at or after it with the brake pedal at or above
    ``brake_threshold_pct`` (the responses of :func:`accelerator_release_time` and :func:`brake_reaction_time`, so
    wherever it is defined it equals their difference with the same thresholds). Per event NaN (NULL), because there
    is no foot movement from the accelerator to the brake to time, when

    * the accelerator is at or below its threshold at the onset sample (the driver was not on it);
    * the brake threshold is reached before the accelerator's (braked before releasing: two-footed, or the brake
      already pressed at the onset); both in the same sample gives 0 s (a movement shorter than the sample step);
    * the accelerator is never released, or the brake is not reached within ``max_s`` of the onset.

    A re-press of the accelerator between release and brake onset stays in the time (the first release counts).
    The window's value is the first event's or the mean (``statistic``)."""
    onsets = _event_onsets(d, sel, o["event"])
    if not len(onsets):
        return math.nan
    rel = _responses(d, onsets, "accel_pedal", o["accel_threshold_pct"], below=True)
    brk = _responses(d, onsets, "brake_pedal", o["brake_threshold_pct"], below=False)
    t = d["t"]
    # rel > onset: on the accelerator at the onset and released later; brk >= rel >= 1: braked, not before releasing
    ok = (rel > onsets) & (brk >= rel) & (t[brk] - t[onsets] <= o["max_s"])
    return _per_event(np.where(ok, t[brk] - t[rel], np.nan), o["statistic"])


def brake_applications(d, sel, o):
    on = d["brake_pedal"] >= o["threshold_pct"]
    rising = np.zeros(len(on), bool)
    rising[1:] = on[1:] & ~on[:-1]
    return float(rising[sel].sum())


@lru_cache(maxsize=64)
def _butter(cutoff_hz: float, fs: float) -> tuple[np.ndarray, np.ndarray]:
    from scipy.signal import butter

    return butter(2, cutoff_hz, fs=fs)


def _lowpass(x: np.ndarray, cutoff_hz: float, fs: float) -> np.ndarray | None:
    """2nd-order Butterworth low-pass, forward and backward (no phase lag); None when `x` is too short. (Second
    order is well conditioned as a transfer function, and filtfilt on it is faster than on second-order sections.)"""
    from scipy.signal import filtfilt

    b, a = _butter(float(cutoff_hz), round(float(fs), 6))
    if len(x) <= 3 * max(len(a), len(b)):
        return None
    return filtfilt(b, a, x)


def reversal_indices(y: np.ndarray, gap: float) -> np.ndarray:
    """Indices of `y` at which a steering reversal of at least `gap` completes (Markkula & Engstrom 2006): the
    stationary points of the filtered signal `y` (where its first difference changes sign or is 0; the ends are
    none), then upward reversals counted greedily (from the lowest point since the last reversal to a point at least
    `gap` above it) and downward ones the same way on -y. Sorted."""
    dy = np.diff(y)
    sign = np.sign(dy)
    idx = np.flatnonzero((sign[1:] != sign[:-1]) | (sign[1:] == 0)) + 1
    pts = y[idx]
    hits = []
    for p in (pts.tolist(), (-pts).tolist()):
        if not p:
            continue
        k = p[0]
        for j, v in enumerate(p):
            if v - k >= gap:
                hits.append(j)
                k = v
            elif v < k:
                k = v
    return np.sort(idx[np.asarray(hits, dtype=np.int64)])


def reversals(y: np.ndarray, gap: float) -> int:
    """Number of steering reversals of at least `gap` in the filtered signal `y` (:func:`reversal_indices`)."""
    return len(reversal_indices(y, gap))


def _grid(d, channel: str, step: float, cutoff_hz: float | None = None, before: bool = False):
    """(signal of `channel` resampled every `step` s over the whole drive, the drive's sample at or before each
    resampled point); with ``cutoff_hz`` low-pass filtered after (``before``: before) resampling; None when the
    drive is too short."""
    t, x = d["t"], d[channel]
    ok = np.isfinite(t) & np.isfinite(x)
    t, x = t[ok], x[ok]
    if len(t) < 2 or t[-1] <= t[0]:
        return None
    if before and cutoff_hz:
        fs = (len(t) - 1) / (t[-1] - t[0])
        if fs > 2 * cutoff_hz:
            x = _lowpass(x, cutoff_hz, fs)
            if x is None:
                return None
    tt = np.arange(t[0], t[-1] + 1e-9, step)
    y = np.interp(tt, t, x)
    if cutoff_hz and not before:
        y = _lowpass(y, cutoff_hz, 1.0 / step)
        if y is None:
            return None
    # the drive's sample at or before each resampled point (interpolating the index is a searchsorted for a
    # monotonic time, at a third of its cost)
    tall = d["t"]
    src = np.floor(np.interp(tt, tall, np.arange(len(tall), dtype=float)) + 1e-9).astype(np.int64)
    return y, src


def steering_reversal_rate(d, sel, o):
    """Reversals per minute. The drive's signal is resampled, filtered and its reversals found once; a window (a
    segment, a region) counts the reversals that complete in it, per minute of it (no filter transients and no
    fresh start of the count at a window's edges)."""
    fs = o["resample_hz"]

    def found():
        g = _grid(d, "steering_angle", 1.0 / fs, o["cutoff_hz"])
        return None if g is None else (reversal_indices(g[0], o["gap_deg"]), g[1])

    r = _cached(d, ("srr", fs, o["cutoff_hz"], o["gap_deg"]), found)
    if r is None:
        return math.nan
    hits, src = r
    m = _mask(sel, len(d["t"]))[src]
    n = np.count_nonzero(m)
    return np.count_nonzero(m[hits]) / (n / fs / 60.0) if n >= 2 else math.nan


ENTROPY_STEP_S = 0.15      # Nakayama et al. (1999): the steering angle every 150 ms
_ENTROPY_EDGES = np.array([-5.0, -2.5, -1.0, -0.5, 0.5, 1.0, 2.5, 5.0])


def prediction_errors(theta: np.ndarray) -> np.ndarray:
    """Errors of the second-order Taylor prediction theta_p(n) = theta(n-1) + (theta(n-1) - theta(n-2)) +
    0.5 ((theta(n-1) - theta(n-2)) - (theta(n-2) - theta(n-3))) (Nakayama et al. 1999, eq. 1)."""
    t1, t2, t3 = theta[2:-1], theta[1:-2], theta[:-3]
    pred = t1 + (t1 - t2) + 0.5 * ((t1 - t2) - (t2 - t3))
    return theta[3:] - pred


def entropy_of(errors: np.ndarray, alpha: float) -> float:
    """Entropy, log base 9, of `errors` in the nine bins bounded by +-0.5, 1, 2.5, 5 alpha."""
    if not len(errors) or not alpha > 0:
        return math.nan
    counts = np.bincount(np.digitize(errors, _ENTROPY_EDGES * alpha), minlength=9)
    p = counts[counts > 0] / len(errors)
    return float(-(p * np.log(p)).sum() / math.log(9))


def steering_entropy(d, sel, o):
    """Entropy of the window's prediction errors; the drive's signal is resampled (after the 2005 method's
    anti-alias filter) and its errors are computed once."""
    def errors():
        cutoff = 0.5 / ENTROPY_STEP_S if o["method"] == "boer2005" else None
        g = _grid(d, "steering_angle", ENTROPY_STEP_S, cutoff, before=True)
        return None if g is None or len(g[0]) < 4 else (prediction_errors(g[0]), g[1][3:])

    e = _cached(d, ("entropy", o["method"]), errors)
    if e is None:
        return math.nan
    err = e[0][_mask(sel, len(d["t"]))[e[1]]]
    if not len(err):
        return math.nan
    alpha = o["alpha_deg"] or float(np.percentile(np.abs(err), 90))
    return entropy_of(err, alpha)


def jerk(d, sel, o):
    j, dt = d["jerk"][sel], d["dt"][sel]
    ok = np.isfinite(j) & (dt > 0)
    if not ok.any():
        return math.nan
    if o["statistic"] == "max_abs":
        return float(np.abs(j[ok]).max())
    return float(math.sqrt((j[ok] ** 2 * dt[ok]).sum() / dt[ok].sum()))


FUNCTIONS = {f.__name__: f for f in (
    speed_mean, speed_sd, speed_exceedance, sdlp, lateral_position_mean, lane_departure, time_headway, distance_gap,
    ttc, brake_reaction_time, accelerator_release_time, accelerator_to_brake_time, steering_reversal_rate,
    steering_entropy, jerk, brake_applications)}


# ------------------------------------------------------------------------------------------- drives and windows
def drive_arrays(cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """One drive's channels (numpy, in idx order) with the derived ``dt`` and ``ds`` (to the next sample, 0 after
    the last), ``a`` filled by central differences of ``v`` where not logged, and ``jerk`` (da/dt to the next
    sample, NaN after the last)."""
    d = dict(cols)
    t = d["t"]
    n = len(t)
    d["dt"] = np.append(np.diff(t), 0.0) if n else t
    d["ds"] = np.append(np.diff(d["s"]), 0.0) if n else t
    a = d.get("a")
    if a is not None and np.isnan(a).any():
        grad = np.gradient(d["v"], t) if n > 1 else np.zeros(n)
        d["a"] = np.where(np.isnan(a), grad, a)
    if a is not None:
        with np.errstate(divide="ignore", invalid="ignore"):
            d["jerk"] = np.append(np.diff(d["a"]) / np.diff(t), np.nan) if n else t
    return d


def region_selection(d, region) -> np.ndarray | None:
    """Boolean mask of the samples of a drive in a region of interest (:class:`study.folder.kpi_spec.Region`);
    None when the drive does not reach it (fewer than two samples in it, or no event)."""
    t = d["t"]
    if region.kind == "position":
        m = (d["s"] >= region.lo) & (d["s"] < region.hi)
    elif region.kind == "time":
        m = (t - t[0] >= region.lo) & (t - t[0] < region.hi)
    elif region.kind == "segment":
        m = d["segment"] == region.segment
    else:
        on = _onsets(d[region.event])
        if not len(on):
            return None
        t0 = t[on[0]]
        m = (t >= t0 - region.lo) & (t < t0 + region.hi)
    return m if m.sum() >= 2 else None


def drive_values(d, kpis, windows) -> list[list[float]]:
    """Per window (a mask or slice; None = not reached -> NaN), the values of `kpis`."""
    out = []
    for sel in windows:
        if sel is None:
            out.append([math.nan] * len(kpis))
            continue
        out.append([FUNCTIONS[k.measure](d, sel, k.opts) for k in kpis])
    return out


def _columns(kpis, regions) -> list[str]:
    chans = [c for k in kpis for c in k.channels] + [r.event for r in regions if r.kind == "event"]
    return list(dict.fromkeys([*_BASE, *chans]))


def iter_drives(con, src: str, columns: list[str], ordered: bool = False):
    """(drive_id, {column: numpy array}, segment labels) of every drive of `src` in drive and idx order, streamed as
    Arrow record batches; ``ordered``: `src` scans in drive order already (else DuckDB sorts it)."""
    if not src.replace("_", "").replace(".", "").isalnum():
        raise ValueError(f"not a relation name: {src!r}")
    order = "" if ordered else " ORDER BY drive_id, idx"
    have = {r[0] for r in con.execute(f"DESCRIBE SELECT * FROM {src}").fetchall()}
    sel = ", ".join(f'"{c}"::DOUBLE AS "{c}"' if c in have else f'NULL::DOUBLE AS "{c}"' for c in columns)
    segs = [r[0] for r in con.execute(f"SELECT DISTINCT segment FROM {src} WHERE segment IS NOT NULL ORDER BY 1")
            .fetchall()]
    con.execute("SET VARIABLE pedas_measure_segments = $s", {"s": segs})
    reader = con.sql(f"""SELECT drive_id, coalesce(list_position(getvariable('pedas_measure_segments'), segment),
                                    0)::INTEGER AS seg_code, {sel} FROM {src}{order}""").to_arrow_reader(_BATCH_ROWS)
    labels = np.array([None, *segs], dtype=object)
    tail: dict[str, np.ndarray] | None = None
    for batch in reader:
        cols = {name: batch.column(i).to_numpy(zero_copy_only=False) for i, name in enumerate(batch.schema.names)}
        if tail is not None:
            cols = {k: np.concatenate((tail[k], v)) for k, v in cols.items()}
        ids = cols["drive_id"]
        cuts = np.flatnonzero(ids[1:] != ids[:-1]) + 1
        bounds = [0, *cuts.tolist()]
        for lo, hi in zip(bounds[:-1], bounds[1:]):
            yield int(ids[lo]), {k: v[lo:hi] for k, v in cols.items()}, labels
        tail = {k: v[bounds[-1]:] for k, v in cols.items()}
    con.execute("RESET VARIABLE pedas_measure_segments")
    if tail is not None and len(tail["drive_id"]):
        yield int(tail["drive_id"][0]), tail, labels


def _one_drive(drive_id, cols, labels, kpis, regions, segment_kpis) -> tuple[list, list]:
    """(rows per segment and overall, rows per region) of one drive."""
    d = drive_arrays({c: v for c, v in cols.items() if c not in ("drive_id", "seg_code")})
    codes = cols["seg_code"]
    d["segment"] = labels[codes]
    keys, windows = [], []
    if segment_kpis:
        for code in pd.unique(codes):
            if code:
                keys.append(labels[code])
                windows.append(codes == code)
    keys.append("overall")
    windows.append(slice(None))
    seg = [(drive_id, key, *vals) for key, vals in zip(keys, drive_values(d, kpis, windows))]
    reg = []
    if regions:
        sels = [region_selection(d, r) for r in regions]
        reg = [(drive_id, r.name, *vals) for r, vals in zip(regions, drive_values(d, kpis, sels))]
    return seg, reg


def measure_kpis(con, src: str, kpis, regions=(), ordered: bool = False) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(values per drive and segment: drive_id, segment (a route segment or ``overall``), one column per measure KPI
    (:class:`study.folder.kpi_spec.MeasureKpi`; segment rows only for those ``per_segment``); values per drive and
    region: drive_id, region, one column per measure KPI, NaN where the drive does not reach the region).
    ``ordered``: `src` scans in drive order (:func:`analysis.drives.kpis.in_drive_order`), so it is not sorted.
    (Threads over drives do not pay: the per-window work is short numpy calls that hold the interpreter lock.)"""
    kpis = list(kpis)
    names = [k.name for k in kpis]
    segment_kpis = any(k.per_segment for k in kpis)
    seg_rows, reg_rows = [], []
    for drive in iter_drives(con, src, _columns(kpis, regions), ordered):
        seg, reg = _one_drive(*drive, kpis, regions, segment_kpis)
        seg_rows += seg
        reg_rows += reg
    seg = pd.DataFrame(seg_rows, columns=["drive_id", "segment", *names])
    reg = pd.DataFrame(reg_rows, columns=["drive_id", "region", *names])
    return seg.astype({n: "float64" for n in names}), reg.astype({n: "float64" for n in names})
