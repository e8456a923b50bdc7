"""Figures of the simulation core, each written as PNG + SVG + PDF: aerodynamic linearisation (Fig. 5a), speed
correction v_corr (Fig. 5b, eq. 11), power-map fit (eq. 5), DP profile (Fig. 2b), green-wave space-time diagram
(Fig. 2a). Every `plot_*(out_dir, ...)` returns the list of files written."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from pedas.constants import ALPHA1, ALPHA2, ALPHA3, DT, KMH, STOP_DWELL
from pedas.params import LEAF, VehicleParams
from pedas.route import Route, StopSign, TrafficLight

STATE_COLOURS = {"green": "#2e9e44", "yellow": "#f2b705", "red": "#d62728"}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# as analysis.render.save_figure (pedas does not import analysis): TrueType fonts in the PDF, fixed SVG ids, no dates
# in any format, so an unchanged figure stays byte-identical between runs and machines
_SAVE_RC = {"pdf.fonttype": 42, "ps.fonttype": 42, "svg.hashsalt": "pedas-study", "svg.fonttype": "path"}
_METADATA = {"png": {"Software": None}, "svg": {"Creator": "pedas-study", "Date": None},
             "pdf": {"Creator": "pedas-study", "Producer": None, "CreationDate": None}}


def _save(fig, out_dir: Path, stem: str) -> list[Path]:
    import matplotlib

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / f"{stem}.{ext}" for ext in _METADATA]
    fig.tight_layout()
    with matplotlib.rc_context(_SAVE_RC):
        for path, (ext, metadata) in zip(paths, _METADATA.items()):
            fig.savefig(path, dpi=150, metadata=metadata)
    _plt().close(fig)
    return paths


def plot_aero_linearisation(out_dir: Path, p: VehicleParams = LEAF,
                            v_range: tuple[float, float] = (0.0, 130 * KMH)) -> list[Path]:
    """Fig. 5a: F_a = 1/2 rho A_f c_w v^2 and its line 1/2 rho A_f c_w (p1 v + p2) over the fitted range."""
    from pedas.vehicle import aero_force, linear_model

    plt = _plt()
    m = linear_model(p, (float(v_range[0]), float(v_range[1])))
    v = np.linspace(v_range[0], v_range[1], 300)
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    ax.plot(v * 3.6, aero_force(v, p), label=r"$F_a=\frac{1}{2}\rho A_f c_w v^2$")
    ax.plot(v * 3.6, m.aero(v), "--", label=rf"$\bar F_a$: $p_1$={m.p1:.2f} m/s, $p_2$={m.p2:.1f} m²/s²")
    ax.set_xlabel("speed $v_h$ (km/h)")
    ax.set_ylabel("aerodynamic force (N)")
    ax.set_title("Aerodynamic resistance and its linearisation")
    ax.grid(alpha=0.3)
    ax.legend()
    return _save(fig, out_dir, "aero_linearisation")


def v_corr(psi):
    """eq. (11): v_corr = alpha1 psi^2 (alpha2 psi^2 + alpha3 psi), m/s, psi = d_rel - d_s in m."""
    psi = np.asarray(psi, dtype=float)
    return ALPHA1 * psi ** 2 * (ALPHA2 * psi ** 2 + ALPHA3 * psi)


def plot_speed_correction(out_dir: Path, psi_range: tuple[float, float] = (-10.0, 0.0)) -> list[Path]:
    """Fig. 5b: the speed correction v_corr(psi) of eq. (11) (applied when psi < 0: inside the safe distance)."""
    plt = _plt()
    psi = np.linspace(psi_range[0], psi_range[1], 300)
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    ax.plot(psi, v_corr(psi), label=rf"$\alpha_1$={ALPHA1}, $\alpha_2$={ALPHA2}, $\alpha_3$={ALPHA3}")
    ax.axhline(0, color="k", lw=0.6)
    ax.axvline(0, color="k", lw=0.6)
    ax.set_xlabel(r"$\psi_k = d_{rel,k} - d_{s,k}$ (m)")
    ax.set_ylabel(r"$v_{corr}$ (m/s)")
    ax.set_title("Speed correction, eq. (11)")
    ax.grid(alpha=0.3)
    ax.legend()
    return _save(fig, out_dir, "speed_correction")


def plot_power_map(out_dir: Path, p: VehicleParams = LEAF) -> list[Path]:
    """Power-map fit: battery power of the loss model vs the quadratic eq. (5) on the traction half-map, and the
    residuals."""
    from pedas.power import battery_power, fit_power_map
    from pedas.vehicle import traction_envelope

    plt = _plt()
    pm, rep = fit_power_map(p)
    v = np.linspace(0.0, 130 * KMH, 120)
    f = np.linspace(0.0, p.F_t_peak, 120)
    V, F = np.meshgrid(v, f)
    inside = F <= traction_envelope(V, p)
    P_model = np.where(inside, battery_power(V, F, 0.0, p=p), np.nan) / 1000
    P_fit = np.where(inside, pm(V, F), np.nan) / 1000
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    levels = np.arange(0, 90, 5)
    cs = axes[0].contour(V * 3.6, F, P_model, levels=levels, colors="C0", linewidths=1.0)
    axes[0].clabel(cs, fmt="%d", fontsize=7)
    axes[0].contour(V * 3.6, F, P_fit, levels=levels, colors="C3", linestyles="--", linewidths=0.9)
    axes[0].plot(v * 3.6, traction_envelope(v, p), "k", lw=1.2)
    axes[0].plot([], [], "C0", label="loss model (kW)")
    axes[0].plot([], [], "C3--", label="quadratic fit eq. (5)")
    axes[0].plot([], [], "k", label="80 kW / 280 Nm envelope")
    axes[0].set_xlabel("speed (km/h)")
    axes[0].set_ylabel("traction force $F_t$ (N)")
    axes[0].set_title("Battery power, traction half-map")
    axes[0].legend(fontsize=8, loc="upper right")
    im = axes[1].pcolormesh(V * 3.6, F, (P_fit - P_model) * 1000, cmap="RdBu_r", shading="auto",
                            vmin=-rep.max_abs_error_W, vmax=rep.max_abs_error_W)
    fig.colorbar(im, ax=axes[1], label="fit - model (W)")
    axes[1].set_xlabel("speed (km/h)")
    axes[1].set_ylabel("traction force $F_t$ (N)")
    axes[1].set_title(f"Residuals: R²={rep.r2:.4f}, RMSE={rep.rmse:.0f} W, max={rep.max_abs_error_W:.0f} W")
    return _save(fig, out_dir, "power_map_fit")


def plot_dp_profile(out_dir: Path, route: Route | None = None, result=None) -> list[Path]:
    """Fig. 2b: v_max (speed and curve limit), v_min and v_DP over the route distance."""
    from pedas.dp import dp_reference

    plt = _plt()
    route = route or Route.synthetic_mixed(stops=[StopSign("SS1", 2000.0)])
    result = result or dp_reference(route)
    fig, ax = plt.subplots(figsize=(10, 3.8))
    ax.plot(route.s / 1000, route.v_max * 3.6, "C3", lw=1.0, label="$v_{max}$ (limit, curves)")
    ax.plot(route.s / 1000, route.v_min * 3.6, "C2", lw=1.0, label="$v_{min}$")
    ax.plot(result.s / 1000, result.v_dp * 3.6, "C0", lw=1.5, label="$v_{DP}$")
    for ss in route.stops:
        ax.axvline(ss.s / 1000, color="k", ls=":", lw=0.8)
        ax.text(ss.s / 1000, 3, f" {ss.ss_id}", fontsize=8)
    for tl in route.lights:
        ax.axvline(tl.s / 1000, color="C1", ls=":", lw=0.8)
    ax.set_xlabel("distance (km)")
    ax.set_ylabel("speed (km/h)")
    ax.set_ylim(0, max(140.0, float(np.max(np.minimum(route.v_max, 60.0))) * 3.6 + 10.0))
    ax.set_title(f"DP reference ({route.name}): {result.energy_wh:.0f} Wh, {result.time_s / 60:.1f} min, "
                 f"w_time={result.w_time:.0f} W, grid {result.ds:.0f} m x {result.dv} m/s")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    return _save(fig, out_dir, "dp_profile")


def green_wave_example() -> Route:
    """The Fig. 2a scenario: a stop sign SS1 and two signalised intersections TL2, TL3 on a 1.2 km urban road."""
    tl2 = TrafficLight("TL2", 450.0, (("green", 25.0), ("yellow", 3.0), ("red", 30.0)), offset=0.0)
    tl3 = TrafficLight("TL3", 950.0, (("green", 25.0), ("yellow", 3.0), ("red", 30.0)), offset=-1.0)
    return Route.synthetic(1200.0, lights=[tl2, tl3], stops=[StopSign("SS1", 150.0)], name="fig2a")


def simulate_reference_following(route: Route, v0: float = 10.0, v_dp: float = 13.8, tau: float = 1.0,
                                 a_lim: tuple[float, float] = (-2.5, 1.5), green_wave: bool = True,
                                 t_end: float = 400.0):
    """A point-mass driver following the reference of `green_wave_reference` (or v_DP with green_wave=False,
    stopping at red), halting STOP_DWELL s at stop signs. Returns arrays t, s, v (for the space-time diagram)."""
    from pedas.greenwave import green_wave_reference

    s, v, t, dwell_until, done = 0.0, v0, 0.0, -1.0, set()
    ts, ss_, vs = [], [], []
    while s < route.length - 1.0 and t < t_end:
        gw = green_wave_reference(route, s, t, v_dp)
        v_ref = gw.v_ref if green_wave else v_dp
        stop = route.next_stop(s)
        if gw.mode == "stop":
            v_ref = min(v_dp, math.sqrt(2 * 1.5 * max(stop.s - s, 0.0)))
        tl = route.next_light(s)
        if tl is not None and (not green_wave or gw.mode == "dp") and tl.state_at(t) != "green":
            v_ref = min(v_ref, math.sqrt(2 * 2.0 * max(tl.s - s - 1.0, 0.0)))  # stop at red
        a = float(np.clip((v_ref - v) / tau, *a_lim))
        v1 = max(v + a * DT, 0.0)
        s1 = s + 0.5 * (v + v1) * DT
        if t < dwell_until:
            s1, v1 = s, 0.0
        elif stop is not None and stop.ss_id not in done and s1 >= stop.s:
            s1, v1, dwell_until = stop.s + 1e-6, 0.0, t + DT + STOP_DWELL
            done.add(stop.ss_id)
        if tl is not None and s1 >= tl.s and tl.state_at(t + DT) == "red" and not green_wave:
            s1, v1 = tl.s - 1e-6, 0.0
        ts.append(t), ss_.append(s), vs.append(v)
        s, v, t = s1, v1, t + DT
    return np.array(ts), np.array(ss_), np.array(vs)


def plot_green_wave(out_dir: Path, route: Route | None = None) -> list[Path]:
    """Fig. 2a: space-time diagram with the lights' phases (bars at their stop lines), a stop sign, the
    trajectory following the green-wave reference and one following v_DP regardless of the SPaT."""
    plt = _plt()
    route = route or green_wave_example()
    t_gw, s_gw, _ = simulate_reference_following(route)
    t_dp, s_dp, _ = simulate_reference_following(route, green_wave=False)
    t_end = float(max(t_gw[-1], t_dp[-1])) + 5.0
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for tl in route.lights:
        starts = tl.phase_starts(0.0, t_end + tl.cycle)
        for (t0, state), (t1, _) in zip(starts, starts[1:]):
            ax.plot([max(t0, 0), min(t1, t_end)], [tl.s, tl.s], color=STATE_COLOURS[state], lw=6,
                    solid_capstyle="butt")
        ax.text(t_end, tl.s, f" {tl.tl_id}", va="center", fontsize=9)
    for ss in route.stops:
        ax.axhline(ss.s, color="k", ls=":", lw=0.8)
        ax.text(t_end, ss.s, f" {ss.ss_id} (stop, {STOP_DWELL:.0f} s)", va="center", fontsize=9)
    ax.plot(t_dp, s_dp, "C7", lw=1.4, label="$v_{DP}$, stops at red")
    ax.plot(t_gw, s_gw, "C0", lw=2.0, label="green-wave reference eq. (1)")
    ax.set_xlim(0, t_end)
    ax.set_ylim(0, route.length)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("distance (m)")
    ax.set_title("Green-wave space-time diagram")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    return _save(fig, out_dir, "green_wave_space_time")


def plot_all(out_dir: Path, route: Route | None = None) -> list[Path]:
    """All core figures into out_dir; the DP profile (Fig. 2b) over `route` (default: a synthetic mixed route)."""
    out: list[Path] = []
    for fn in (plot_aero_linearisation, plot_speed_correction, plot_power_map, plot_green_wave):
        out += fn(out_dir)
    return out + plot_dp_profile(out_dir, route=route)
