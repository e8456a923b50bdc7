"""Distance-indexed route description: road profile, speed limits, traffic lights with a fixed-time SPaT, stop signs.

Everything is indexed by the distance `s` (m) along the route. Traffic lights run a deterministic, periodic
signal plan (SPaT) so that the green-wave reference (eq. 1) can look ahead. Plain numpy; the concrete study
route (13.2 km, built from the SUMO network) is created elsewhere with this type.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from pedas.constants import HIGHWAY_MIN_SPEED, KMH

STATES = ("green", "yellow", "red")
D_STOPLINE_DEFAULT = 5.0  # m, d_s,ITS: the soft stop-line approach band of eq. (8b) (not printed in the paper)
A_LAT_MAX_DEFAULT = 2.0  # m/s^2, comfortable lateral acceleration for the curve speed limit (not printed)
CLOCK_MAX = 1e9  # s (32 years): |t| a signal program is evaluated at; the float spacing there is 1.2e-7 s, beyond
                 # ~1e16 s adding a phase no longer moves the clock, and a scan over phase starts would never end


def braking_envelope(s: np.ndarray, v: np.ndarray, b: float) -> np.ndarray:
    """Backward pass over a speed profile v(s) (m, m/s): at each point the highest speed from which every later
    value is reached braking at b (m/s^2), v_env,i = min(v_i, sqrt(v_env,i+1^2 + 2 b ds))."""
    env = np.array(v, dtype=float)
    ds = np.diff(np.asarray(s, float))
    two_b = 2.0 * b
    for i in range(env.size - 2, -1, -1):  # ~13k points, once per drive / controller
        nxt = math.sqrt(env[i + 1] * env[i + 1] + two_b * ds[i])
        if nxt < env[i]:
            env[i] = nxt
    return env


@dataclass(frozen=True)
class TrafficLight:
    """A fixed-time traffic light at route position `s` (its stop line, m).

    phases: ((state, duration_s), ...) with state in green|yellow|red; the cycle starts (first phase begins) at
    absolute time `offset` s and repeats forever (also before the offset).
    """

    tl_id: str
    s: float
    phases: tuple[tuple[str, float], ...]
    offset: float = 0.0

    def __post_init__(self) -> None:
        if not self.phases:
            raise ValueError(f"traffic light {self.tl_id}: no phases")
        for state, dur in self.phases:
            if state not in STATES:
                raise ValueError(f"traffic light {self.tl_id}: unknown state {state!r} (expected {STATES})")
            if not dur > 0:
                raise ValueError(f"traffic light {self.tl_id}: phase duration must be > 0, got {dur}")
        object.__setattr__(self, "phases", tuple((str(st), float(d)) for st, d in self.phases))
        object.__setattr__(self, "s", float(self.s))
        object.__setattr__(self, "offset", float(self.offset))
        object.__setattr__(self, "_cycle", float(sum(d for _, d in self.phases)))   # looked up every control step

    @property
    def cycle(self) -> float:
        """Cycle time in s."""
        return self._cycle

    def _check_clock(self, t: float) -> None:
        if not abs(t) <= CLOCK_MAX:   # also nan
            raise ValueError(f"traffic light {self.tl_id}: time {t!r} s outside the signal clock's range "
                             f"(|t| <= {CLOCK_MAX:g} s)")

    def _locate(self, t: float) -> tuple[int, float, float]:
        """(phase index, absolute start of that phase, absolute start of the cycle containing t); ValueError for a
        t that is not finite or beyond CLOCK_MAX."""
        self._check_clock(t)
        c = self.cycle
        k = math.floor((t - self.offset) / c)
        c0 = self.offset + k * c
        tau = t - c0
        acc = 0.0
        for i, (_, d) in enumerate(self.phases):
            if tau < acc + d:
                return i, c0 + acc, c0
            acc += d
        return len(self.phases) - 1, c0 + acc - self.phases[-1][1], c0  # float edge: tau == c

    def state_at(self, t: float) -> str:
        """Signal state at absolute time t."""
        return self.phases[self._locate(t)[0]][0]

    def remaining(self, t: float) -> float:
        """Seconds left in the phase active at time t (SPaT 'time to change')."""
        i, start, _ = self._locate(t)
        return start + self.phases[i][1] - t

    def state_remaining(self, t: float) -> tuple[str, float]:
        """(:meth:`state_at`, :meth:`remaining`) at time t from one look-up of the active phase: the same values."""
        i, start, _ = self._locate(t)
        state, dur = self.phases[i]
        return state, start + dur - t

    def phase_starts(self, t0: float, t1: float) -> list[tuple[float, str]]:
        """All phase starts (time, state) with t0 < time <= t1, plus the phase active at t0 as (its start, state)."""
        i, start, _ = self._locate(t0)
        return self._starts_from(i, start, t1)

    def spat(self, t0: float, horizon: float) -> tuple[str, float, list[tuple[float, str]]]:
        """(:meth:`state_at`, :meth:`remaining` and :meth:`next_phase_starts` at t0 over `horizon` s), from one
        look-up of the active phase: the same numbers as the three calls."""
        i, start, _ = self._locate(t0)
        state, dur = self.phases[i]
        return state, start + dur - t0, [(t, st) for t, st in self._starts_from(i, start, t0 + horizon) if t > t0]

    def _starts_from(self, i: int, start: float, t1: float) -> list[tuple[float, str]]:
        """Phase i (starting at `start`) and the phase starts after it up to t1. The scan is bounded by the phases
        that fit between start and t1 (one cycle of margin for rounding); t1 beyond CLOCK_MAX is a ValueError."""
        self._check_clock(t1)
        out = [(start, self.phases[i][0])]
        t = start
        n = len(self.phases)
        for _ in range(n * (math.floor(max(t1 - start, 0.0) / self.cycle) + 2)):
            t += self.phases[i][1]
            i = (i + 1) % n
            if t > t1:
                return out
            out.append((t, self.phases[i][0]))
        raise ValueError(f"traffic light {self.tl_id}: phase starts from {start!r} s do not reach {t1!r} s (phases too "
                         "short for the clock's precision)")

    def next_phase_starts(self, t0: float, horizon: float) -> list[tuple[float, str]]:
        """Phase changes (absolute time, new state) in (t0, t0 + horizon]."""
        return [(t, st) for t, st in self.phase_starts(t0, t0 + horizon) if t > t0]

    def green_windows(self, t0: float, t1: float) -> list[tuple[float, float]]:
        """Green intervals [g, r) (absolute s) that overlap [t0, t1], consecutive green phases merged.

        Not clipped: a window already open at t0 starts before t0, and the last window may end after t1 — its
        end r is the real start of the next non-green phase (needed by eq. 1). Yellow counts as not green.
        """
        # extend the scan one cycle past t1 so the end of the last window is known
        starts = self.phase_starts(t0, t1 + self.cycle + 1e-9)
        out: list[tuple[float, float]] = []
        g = None
        for t, st in starts:
            if st == "green" and g is None:
                g = t
            elif st != "green" and g is not None:
                if t > t0 and g <= t1:
                    out.append((g, t))
                g = None
        if g is not None and g <= t1:  # green to the end of the scan (all-green plan)
            out.append((g, math.inf))
        return out


@dataclass(frozen=True)
class StopSign:
    """A stop sign with its stop line at route position `s` (m); the driver halts STOP_DWELL s there."""

    ss_id: str
    s: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "s", float(self.s))


@dataclass(eq=False)
class Route:
    """A route sampled on an ascending distance grid `s` (m, from 0).

    Per grid point: z elevation (m), grade theta (rad), curvature kappa (1/m, signed), speed_limit (legal, m/s),
    v_min (m/s; 0 in town, 80 km/h on the highway), segment ('urban'|'highway'). Plus traffic lights, stop signs,
    the stop-line approach band d_stopline = d_s,ITS (m, eq. 8b) and a_lat_max (m/s^2) for the curve limit.
    """

    name: str
    s: np.ndarray
    z: np.ndarray
    grade: np.ndarray
    curvature: np.ndarray
    speed_limit: np.ndarray
    v_min: np.ndarray
    segment: np.ndarray
    lights: tuple[TrafficLight, ...] = ()
    stops: tuple[StopSign, ...] = ()
    d_stopline: float = D_STOPLINE_DEFAULT
    a_lat_max: float = A_LAT_MAX_DEFAULT
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.s = np.asarray(self.s, dtype=float)
        n = self.s.size
        if n < 2:
            raise ValueError("route needs at least two grid points")
        if abs(self.s[0]) > 1e-9 or np.any(np.diff(self.s) <= 0):
            raise ValueError("route grid s must start at 0 and be strictly ascending")
        for name in ("z", "grade", "curvature", "speed_limit", "v_min"):
            arr = np.asarray(getattr(self, name), dtype=float)
            if arr.ndim == 0:
                arr = np.full(n, float(arr))
            if arr.shape != (n,):
                raise ValueError(f"route field {name}: expected {n} values, got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"route field {name}: non-finite values")
            setattr(self, name, arr)
        seg = np.asarray(self.segment, dtype=object)
        if seg.ndim == 0:
            seg = np.full(n, str(seg), dtype=object)
        if seg.shape != (n,) or not set(seg.tolist()) <= {"urban", "highway"}:
            raise ValueError("route field segment: expected one of 'urban'|'highway' per grid point")
        self.segment = seg
        if np.any(self.speed_limit <= 0):
            raise ValueError("route speed_limit must be > 0")
        self.lights = tuple(sorted(self.lights, key=lambda x: x.s))
        self.stops = tuple(sorted(self.stops, key=lambda x: x.s))
        for obj in (*self.lights, *self.stops):
            if not 0 <= obj.s <= self.length:
                raise ValueError(f"{obj} lies outside the route [0, {self.length}] m")

    # --- derived profiles -------------------------------------------------------------------------------------
    @property
    def length(self) -> float:
        """Route length in m."""
        return float(self.s[-1])

    def _cached(self, key: str, compute):
        # the arrays are fixed after construction (treat a Route as immutable); derived profiles are computed once
        if key not in self._cache:
            self._cache[key] = compute()
        return self._cache[key]

    @property
    def v_curve(self) -> np.ndarray:
        """Curve speed limit sqrt(a_lat_max / |kappa|) in m/s (inf on straight road)."""
        def compute():
            k = np.abs(self.curvature)
            with np.errstate(divide="ignore"):
                return np.where(k > 1e-9, np.sqrt(self.a_lat_max / np.maximum(k, 1e-12)), np.inf)
        return self._cached("v_curve", compute)

    @property
    def v_max(self) -> np.ndarray:
        """Maximum allowable speed min(speed_limit, v_curve) in m/s (Fig. 2b)."""
        return self._cached("v_max", lambda: np.minimum(self.speed_limit, self.v_curve))

    def at(self, s, field: str):
        """Linear interpolation of a numeric field ('z', 'grade', 'v_max', ...) at distance(s) s; 'segment' gives
        the segment of the grid interval containing s. Clamped to the route ends."""
        s_arr = np.asarray(s, dtype=float)
        if field == "segment":
            idx = np.clip(np.searchsorted(self.s, s_arr, side="right") - 1, 0, self.s.size - 1)
            out = self.segment[idx]
            return str(out) if np.ndim(out) == 0 else out
        values = getattr(self, field)
        out = np.interp(s_arr, self.s, values)
        return float(out) if out.ndim == 0 else out

    def min_over(self, s0: float, s1: float, field: str = "v_max") -> float:
        """Minimum of a numeric field over [s0, s1] (grid points inside plus both interpolated ends)."""
        lo, hi = min(s0, s1), max(s0, s1)
        values = getattr(self, field)
        i0, i1 = np.searchsorted(self.s, lo, side="left"), np.searchsorted(self.s, hi, side="right")
        m = min(self.at(lo, field), self.at(hi, field))
        return float(min(m, values[i0:i1].min())) if i1 > i0 else float(m)

    # --- objects ahead ----------------------------------------------------------------------------------------
    def next_light(self, s: float) -> TrafficLight | None:
        """The first traffic light whose stop line is at or ahead of s (None when none is left)."""
        for tl in self.lights:
            if tl.s >= s:
                return tl
        return None

    def next_stop(self, s: float) -> StopSign | None:
        """The first stop sign whose stop line is at or ahead of s (None when none is left)."""
        for ss in self.stops:
            if ss.s >= s:
                return ss
        return None

    # --- constructors -----------------------------------------------------------------------------------------
    @classmethod
    def synthetic(cls, length: float = 1000.0, ds: float = 10.0, speed_limit: float = 50 * KMH,
                  v_min: float = 0.0, grade: float | Sequence[float] | np.ndarray = 0.0,
                  curvature: float | Sequence[float] | np.ndarray = 0.0, segment: str = "urban",
                  lights: Sequence[TrafficLight] = (), stops: Sequence[StopSign] = (),
                  name: str = "synthetic", d_stopline: float = D_STOPLINE_DEFAULT,
                  a_lat_max: float = A_LAT_MAX_DEFAULT) -> "Route":
        """A straight test route of `length` m on a grid of `ds` m with constant (or given per-point) profiles.

        z is integrated from the grade. Scalars are broadcast; arrays must match the grid.
        """
        if not length > 0 or not ds > 0:
            raise ValueError("length and ds must be > 0")
        n = int(round(length / ds)) + 1
        s = np.linspace(0.0, length, n)
        gr = np.broadcast_to(np.asarray(grade, dtype=float), (n,)).copy()
        z = np.concatenate([[0.0], np.cumsum(np.diff(s) * np.tan(0.5 * (gr[1:] + gr[:-1])))])
        return cls(name=name, s=s, z=z, grade=gr,
                   curvature=np.broadcast_to(np.asarray(curvature, dtype=float), (n,)).copy(),
                   speed_limit=np.full(n, float(speed_limit)), v_min=np.full(n, float(v_min)),
                   segment=np.full(n, segment, dtype=object), lights=tuple(lights), stops=tuple(stops),
                   d_stopline=d_stopline, a_lat_max=a_lat_max)

    @classmethod
    def synthetic_mixed(cls, urban_m: float = 6000.0, highway_m: float = 7200.0, ds: float = 10.0,
                        urban_limit: float = 50 * KMH, highway_limit: float = 120 * KMH,
                        hill_amplitude_m: float = 15.0, lights: Sequence[TrafficLight] = (),
                        stops: Sequence[StopSign] = (), name: str = "synthetic-mixed") -> "Route":
        """An urban + highway test route (default 13.2 km like the study route) with a smooth hilly profile,
        two curves in town and the highway minimum speed of 80 km/h; for benchmarks and figures."""
        length = urban_m + highway_m
        n = int(round(length / ds)) + 1
        s = np.linspace(0.0, length, n)
        z = hill_amplitude_m * np.sin(2 * np.pi * s / 4000.0) * np.sin(np.pi * s / length)
        grade = np.arctan(np.gradient(z, s))
        hw = s >= urban_m
        curvature = np.zeros(n)
        for c, r in ((1500.0, 40.0), (4200.0, 60.0)):  # two town curves (radius m) of ~60 m arc
            curvature[np.abs(s - c) <= 30.0] = 1.0 / r
        speed_limit = np.where(hw, highway_limit, urban_limit)
        v_min = np.where(hw, HIGHWAY_MIN_SPEED, 0.0)
        # the on-ramp: no minimum on the first 300 m of highway (acceleration lane)
        v_min[(s >= urban_m) & (s < urban_m + 300.0)] = 0.0
        segment = np.where(hw, "highway", "urban").astype(object)
        return cls(name=name, s=s, z=z, grade=grade, curvature=curvature, speed_limit=speed_limit, v_min=v_min,
                   segment=segment, lights=tuple(lights), stops=tuple(stops))
