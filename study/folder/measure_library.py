"""The shipped standard driving measures: each named by the SAE J2944 term it follows and, where one exists, the paper
that defines it, with its options, included into a study by name in its KPI file (docs/measures.md)::

    [measures]
    srr = { measure = "steering_reversal_rate", gap_deg = 2.0 }
    thw = { measure = "time_headway", option = "A", statistic = "min" }

Each :class:`Measure` names its source (the J2944 term and the defining paper by author and year, without J2944
section numbers; the full references, and why no section numbers, are in docs/measures.md), the channels it reads
(the log mapping's standard names: ``t``, ``s``, ``v``, ``a``, ``speed_limit``, ``leader_gap``, ``leader_v``, and the
extra channels ``lat_pos`` (m, left of the lane centre positive), ``steering_angle`` (deg), ``brake_pedal`` and
``accel_pedal`` (% of travel)), its options with their defaults and allowed ranges, and the sentence a methods
section must carry (J2944 asks that the options used be reported). The computations live in
:mod:`analysis.drives.measures`; this module is the catalogue and its checks, and imports nothing heavy.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

#: channels every stored drive has (the drive log's own columns; ``a`` is filled from ``v`` where not logged)
ALWAYS_PRESENT = ("t", "s", "v", "a", "speed_limit")
_J2944 = "SAE J2944 (2015)"


@dataclass(frozen=True)
class Option:
    """One option of a measure: a number in [lo, hi], a choice, or a channel name (``kind``)."""

    name: str
    default: Any
    kind: str = "number"          # number | choice | channel
    lo: float | None = None
    hi: float | None = None
    choices: tuple[str, ...] = ()
    unit: str = ""
    text: str = ""

    def check(self, value: Any) -> str | None:
        """None when `value` is allowed, else a one-line reason."""
        if self.kind == "choice":
            return None if value in self.choices else f"must be one of {'|'.join(self.choices)}, not {value!r}"
        if self.kind == "channel":
            ok = isinstance(value, str) and value.replace("_", "").isalnum() and value[:1].isalpha()
            return None if ok else f"must name a channel of the drive log, not {value!r}"
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            return f"must be a number, not {value!r}"
        if (self.lo is not None and value < self.lo) or (self.hi is not None and value > self.hi):
            return f"must be in [{self.lo:g}, {self.hi:g}] {self.unit}".rstrip() + f", not {value:g}"
        return None


@dataclass(frozen=True)
class Measure:
    """A shipped measure (module docstring); ``methods`` is a template of the methods sentence over its options."""

    name: str
    title: str
    unit: str
    source: str
    channels: tuple[str, ...]
    options: tuple[Option, ...] = ()
    methods: str = ""
    units: tuple[tuple[str, str], ...] = ()   # statistic -> unit, where the statistic changes it

    def option(self, name: str) -> Option | None:
        return next((o for o in self.options if o.name == name), None)

    def defaults(self) -> dict[str, Any]:
        return {o.name: o.default for o in self.options}

    def unit_of(self, opts: dict[str, Any]) -> str:
        return dict(self.units).get(opts.get("statistic"), self.unit)

    def channels_of(self, opts: dict[str, Any]) -> tuple[str, ...]:
        """The channels the measure reads with options `opts` (its own and any channel option's)."""
        extra = tuple(opts[o.name] for o in self.options if o.kind == "channel" and opts.get(o.name))
        return tuple(dict.fromkeys((*self.channels, *extra)))

    def sentence(self, opts: dict[str, Any], label: str = "") -> str:
        """The methods sentence with options `opts` (defaults filled in)."""
        full = {**self.defaults(), **opts}
        text = self.methods.format(**full, **{f"{k}_text": _choice_text(self, k, v) for k, v in full.items()})
        return f"{label or self.title}: {text} ({self.source})."


def _choice_text(measure: Measure, key: str, value: Any) -> str:
    return _CHOICE_TEXT.get((measure.name, key, value), _CHOICE_TEXT.get((key, value), str(value)))


def _stat(choices: tuple[str, ...], default: str | None = None) -> Option:
    return Option("statistic", default or choices[0], "choice", choices=choices)


_HEADWAY_POINTS = {"A": "front bumper to front bumper (the lead vehicle's length added to the gap)",
                   "B": "rear bumper to rear bumper (the subject vehicle's length added to the gap)",
                   "C": "front bumper of the subject vehicle to rear bumper of the lead vehicle (the time gap)"}
_CHOICE_TEXT: dict[tuple, str] = {
    **{("option", k): v for k, v in _HEADWAY_POINTS.items()},
    ("method", "nakayama1999"): ("the 1999 method (Nakayama et al. 1999): the signal sampled every 150 ms without a "
                                 "filter"),
    ("method", "boer2005"): ("the 2005 method (Boer et al. 2005): the signal low-pass filtered (2nd-order Butterworth "
                             "at half the resampling rate) before it is resampled every 150 ms"),
    ("statistic", "min"): "minimum", ("statistic", "mean"): "mean",
    ("statistic", "share_below"): "share of the time with a lead vehicle below the threshold",
    ("statistic", "time_below_s"): "time below the threshold", ("statistic", "count"): "number",
    ("statistic", "duration_mean_s"): "mean duration", ("statistic", "duration_total_s"): "total duration",
    ("statistic", "time_s"): "time", ("statistic", "distance_m"): "distance", ("statistic", "share"): "share of time",
    ("statistic", "first"): "first event's", ("statistic", "max_abs"): "maximum absolute", ("statistic", "rms"): "RMS",
}

_EVENT = Option("event", None, "channel", text="0/1 channel whose rising edge is the event (e.g. takeover_request)")
_MAX_S = Option("max_s", 10.0, lo=0.1, hi=120.0, unit="s", text="no response within this time: no value (NULL)")


def _brake_pct(name: str = "threshold_pct") -> Option:
    """The brake pedal travel that is braking (the brake reaction time's and the transition time's)."""
    return Option(name, 5.0, lo=0.1, hi=100.0, unit="%", text="brake pedal travel that is braking")


def _accel_pct(name: str = "threshold_pct") -> Option:
    """The accelerator pedal travel that is released (the release time's and the transition time's)."""
    return Option(name, 1.0, lo=0.0, hi=100.0, unit="%", text="accelerator pedal travel that is released")


MEASURES: dict[str, Measure] = {m.name: m for m in (
    Measure("speed_mean", "Mean speed", "m/s", f"{_J2944}, speed", ("v",),
            methods="arithmetic mean of the logged speed samples"),
    Measure("speed_sd", "Standard deviation of speed", "m/s", f"{_J2944}, speed", ("v",),
            methods="sample standard deviation (n - 1) of the logged speed samples"),
    Measure("speed_exceedance", "Speed exceedance", "s", f"{_J2944}, speeding", ("v", "speed_limit", "s"),
            (_stat(("time_s", "distance_m", "share")),
             Option("tolerance_kmh", 0.0, lo=0.0, hi=50.0, unit="km/h", text="speed above the limit tolerated")),
            "{statistic_text} with the speed above the posted limit plus {tolerance_kmh:g} km/h, summed over the "
            "sampling intervals whose first sample exceeds it",
            units=(("distance_m", "m"), ("share", "1"))),
    Measure("sdlp", "SDLP", "m", f"{_J2944}, standard deviation of lane position (SDLP)", ("lat_pos",),
            methods="sample standard deviation (n - 1) of the lateral position of the vehicle centre relative to the "
                    "lane centre, over all samples"),
    Measure("lateral_position_mean", "Mean lateral position", "m", f"{_J2944}, lane position", ("lat_pos",),
            methods="mean lateral position of the vehicle centre relative to the lane centre, left positive"),
    Measure("lane_departure", "Lane departures", "", f"{_J2944}, lane departure", ("lat_pos",),
            (_stat(("count", "duration_mean_s", "duration_total_s")),
             Option("lane_width_m", 3.5, lo=2.0, hi=6.0, unit="m"),
             Option("vehicle_width_m", 1.8, lo=0.5, hi=3.0, unit="m", text="width at the outermost point considered"),
             Option("min_duration_s", 0.0, lo=0.0, hi=10.0, unit="s")),
            "{statistic_text} of lane departures, a departure lasting from the first sample at which an outer edge "
            "of the {vehicle_width_m:g} m wide vehicle lies beyond a boundary of the {lane_width_m:g} m lane to the "
            "first sample inside again, departures shorter than {min_duration_s:g} s not counted",
            units=(("duration_mean_s", "s"), ("duration_total_s", "s"))),
    Measure("time_headway", "Time headway", "s", f"{_J2944}, time headway", ("v", "leader_gap"),
            (_stat(("min", "mean", "share_below")), Option("option", "A", "choice", choices=("A", "B", "C")),
             Option("lead_length_m", 4.5, lo=1.0, hi=25.0, unit="m"),
             Option("subject_length_m", 4.5, lo=1.0, hi=25.0, unit="m"),
             Option("max_s", 10.0, lo=0.5, hi=60.0, unit="s", text="longer headways are not car following"),
             Option("threshold_s", 1.0, lo=0.1, hi=10.0, unit="s", text="for share_below")),
            "{statistic_text} time headway measured {option_text}, divided by the subject vehicle's speed, over the "
            "samples with a lead vehicle present and a headway of at most {max_s:g} s (threshold {threshold_s:g} s; "
            "lead vehicle {lead_length_m:g} m, subject vehicle {subject_length_m:g} m long)",
            units=(("share_below", "1"),)),
    Measure("distance_gap", "Gap", "m", f"{_J2944}, gap", ("leader_gap",),
            (_stat(("min", "mean")),),
            "{statistic_text} distance from the front bumper of the subject vehicle to the rear bumper of the lead "
            "vehicle, over the samples with a lead vehicle present"),
    Measure("ttc", "Time to collision", "s", f"{_J2944}, time to collision; Hayward (1972)",
            ("v", "leader_gap", "leader_v"),
            (_stat(("min", "time_below_s")),
             Option("threshold_s", 3.0, lo=0.1, hi=20.0, unit="s", text="for time_below_s")),
            "{statistic_text} time to collision, the gap divided by the closing speed at constant speeds, over the "
            "samples where the subject vehicle closes in on a lead vehicle (threshold {threshold_s:g} s)"),
    Measure("brake_reaction_time", "Brake reaction time", "s", f"{_J2944}, reaction time", ("brake_pedal",),
            (_EVENT, _brake_pct(), _stat(("first", "mean")), _MAX_S),
            "{statistic_text} time from the onset of the event ({event} rising) to the first sample with the brake "
            "pedal at or above {threshold_pct:g} % of its travel, no response within {max_s:g} s counted as missing"),
    Measure("accelerator_release_time", "Accelerator release time", "s", f"{_J2944}, reaction time",
            ("accel_pedal",),
            (_EVENT, _accel_pct(), _stat(("first", "mean")), _MAX_S),
            "{statistic_text} time from the onset of the event ({event} rising) to the first sample with the "
            "accelerator pedal at or below {threshold_pct:g} % of its travel, no release within {max_s:g} s counted "
            "as missing"),
    Measure("accelerator_to_brake_time", "Accelerator-to-brake transition time", "s",
            f"{_J2944}, reaction time; Liebermann et al. (1995), accelerator-to-brake movement time",
            ("accel_pedal", "brake_pedal"),
            (_EVENT, _accel_pct("accel_threshold_pct"), _brake_pct("brake_threshold_pct"), _stat(("first", "mean")),
             _MAX_S),
            "{statistic_text} time from the release of the accelerator pedal (its first sample at or below "
            "{accel_threshold_pct:g} % of its travel after the onset of the event, {event} rising) to brake onset (the "
            "first sample with the brake pedal at or above {brake_threshold_pct:g} %), counted as missing when the "
            "accelerator was already released at the onset, when the brake was reached before the accelerator was "
            "released, or when no brake onset followed within {max_s:g} s of the onset"),
    Measure("steering_reversal_rate", "Steering reversal rate", "1/min",
            f"{_J2944}, steering wheel reversal rate; Markkula & Engstr\u00f6m (2006)", ("steering_angle",),
            (Option("gap_deg", 2.0, lo=0.1, hi=20.0, unit="deg", text="smallest counted reversal"),
             Option("cutoff_hz", 6.0, lo=0.1, hi=15.0, unit="Hz", text="low-pass cut-off"),
             Option("resample_hz", 32.0, lo=1.0, hi=200.0, unit="Hz")),
            "reversals per minute of the steering wheel angle, resampled at {resample_hz:g} Hz, low-pass filtered "
            "with a 2nd-order Butterworth filter at {cutoff_hz:g} Hz (forward and backward, no phase lag), a "
            "reversal being a change of direction between stationary points by at least {gap_deg:g} deg, counted "
            "upwards and downwards"),
    Measure("steering_entropy", "Steering entropy", "1",
            f"{_J2944}, steering entropy; Nakayama et al. (1999); Boer et al. (2005)",
            ("steering_angle",),
            (Option("method", "boer2005", "choice", choices=("boer2005", "nakayama1999")),
             Option("alpha_deg", 0.0, lo=0.0, hi=45.0, unit="deg",
                    text="90th percentile of |prediction error| of a baseline; 0: of the drive itself")),
            "entropy (log base 9) of the second-order Taylor prediction errors of the steering wheel angle in nine "
            "bins bounded by 0.5, 1, 2.5 and 5 alpha, by {method_text}; alpha {alpha_deg:g} deg "
            "(0: the 90th percentile of the absolute prediction errors of the same drive and window)"),
    Measure("jerk", "Longitudinal jerk", "m/s^3", f"{_J2944}, jerk", ("a",),
            (_stat(("max_abs", "rms")),),
            "{statistic_text} longitudinal jerk, the change of the longitudinal acceleration between consecutive "
            "samples divided by their time step (RMS weighted by the time step)"),
    Measure("brake_applications", "Brake applications", "", f"{_J2944}, brake application", ("brake_pedal",),
            (Option("threshold_pct", 5.0, lo=0.1, hi=100.0, unit="%"),),
            "number of times the brake pedal reaches {threshold_pct:g} % of its travel from below"),
)}


def shipped() -> list[str]:
    """Names of the shipped measures, sorted."""
    return sorted(MEASURES)


def resolve(measure: Measure, raw: dict[str, Any]) -> tuple[dict[str, Any], list[tuple[str, str]]]:
    """(options with defaults filled in, problems as (option key, reason)) of the options `raw` a study gives."""
    problems = []
    opts = measure.defaults()
    for key, value in raw.items():
        opt = measure.option(key)
        if opt is None:
            known = ", ".join(o.name for o in measure.options) or "none"
            problems.append((key, f"is not an option of {measure.name} (options: {known})"))
            continue
        reason = opt.check(value)
        if reason:
            problems.append((key, reason))
        else:
            opts[key] = float(value) if opt.kind == "number" else value
    for opt in measure.options:
        if opt.kind == "channel" and not opts.get(opt.name):
            problems.append((opt.name, f"{measure.name} needs {opt.name} = \"<channel>\" ({opt.text})"))
    if measure.name == "steering_reversal_rate" and opts["resample_hz"] <= 2 * opts["cutoff_hz"]:
        problems.append(("resample_hz", f"must be above twice cutoff_hz ({2 * opts['cutoff_hz']:g} Hz)"))
    return opts, problems
