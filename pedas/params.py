"""Vehicle parameters the paper leaves open: the Nissan Leaf (ZE0/AZE0, 2013-2017, 24/30 kWh) host vehicle.

The paper names the Leaf as host vehicle and takes its vehicle and battery models from Lin et al. (2014) without
printing the numbers. Every value below therefore comes from public manufacturer data or is a documented
engineering assumption; the source is written next to each value and collected in docs/vehicle_and_references.md.
Constants the paper prints (DT, N, alphas, ...) live in `pedas.constants`, not here.

The second half holds the controller's tuning: :class:`ControllerParams` (weights of both MPCs, QP backend and its
settings, the thresholds of the pEDAS logic, the HUD and the green wave), one settings object per controller in the
manner of do-mpc's settings dict, with the default :data:`CONTROLLER`. docs/controller.md gives the reasoning of each
value.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from pedas.constants import HUD_BAND, KMH


@dataclass(frozen=True)
class VehicleParams:
    """Longitudinal, drivetrain and battery parameters of a BEV (SI units)."""

    m_v: float  # kg, vehicle mass incl. driver (rolling and gradient resistance), eq. (2)
    m_eq: float  # kg, equivalent mass incl. rotating parts (inertia term), eq. (2)
    c_w: float  # -, aerodynamic drag coefficient
    A_f: float  # m^2, frontal area
    rho: float  # kg/m^3, air density
    c_r: float  # -, rolling resistance coefficient
    g: float  # m/s^2
    r_wheel: float  # m, wheel (rolling) radius
    i_gear: float  # -, single-speed reduction ratio motor : wheel
    P_max: float  # W, motor peak mechanical power
    T_max: float  # Nm, motor peak torque
    omega_max: float  # rad/s, motor maximum speed
    F_b_max: float  # N, maximum total (friction + regenerative) braking force, eq. (6b)
    P_regen_max: float  # W, maximum regenerative power at the motor shaft
    v_regen_fade: float  # m/s, below this speed regeneration fades linearly to zero
    P_aux: float  # W, auxiliary load drawn from the battery (12 V system, controls; no HVAC)
    eta_gear: float  # -, reduction gear efficiency (both directions)
    k_copper: float  # W/(Nm)^2, motor/inverter copper loss coefficient  (loss = k_c T^2)
    k_iron: float  # W/(rad/s), iron loss coefficient                   (loss = k_i omega)
    k_wind: float  # W/(rad/s)^3, windage loss coefficient               (loss = k_w omega^3)
    P_const_loss: float  # W, speed-independent inverter/electronics loss while the motor is energised
    V_oc: float  # V, battery pack open-circuit voltage (nominal)
    R_int: float  # Ohm, battery pack internal resistance
    E_batt: float  # Wh, battery gross capacity

    @property
    def F_t_peak(self) -> float:
        """N, traction force at the wheels at peak motor torque (below base speed)."""
        return self.T_max * self.i_gear * self.eta_gear / self.r_wheel

    @property
    def v_top(self) -> float:
        """m/s, vehicle speed at the motor's maximum speed."""
        return self.omega_max * self.r_wheel / self.i_gear


# Nissan Leaf, 24 kWh (2013-2015 AZE0; the 30 kWh 2016-2017 car shares body, motor and gear; +~20 kg).
LEAF = VehicleParams(
    # Curb mass ~1,490-1,525 kg by trim (Nissan 2013 Leaf specifications) + ~80 kg driver: 1,600 kg (rounded).
    m_v=1600.0,
    # Rotating masses (wheels/tyres, rotor x i_gear^2, gear) add ~4 % for single-speed EVs
    # (Guzzella & Sciarretta, Vehicle Propulsion Systems, typical 1.03-1.05 for a fixed ratio): 1.04 * m_v.
    m_eq=1664.0,
    # Drag coefficient 0.28 (Nissan's published value for the Leaf; 0.29 is quoted for some markets) and frontal
    # area 2.29 m^2 (width 1.770 m x height 1.550 m x 0.835 fill factor - an estimate, not a published figure).
    c_w=0.28,
    A_f=2.29,
    rho=1.2,  # kg/m^3, dry air at 20 C and sea level (ISO standard atmosphere 1.225 at 15 C)
    # Low rolling resistance tyres (Bridgestone Ecopia EP422 205/55R16, OEM on the Leaf). EU tyre-label classes
    # B/C span 6.6-9.0 kg/t; 0.009 (upper end, includes bearing/brake drag) is used - see the NEDC calibration below.
    c_r=0.009,
    g=9.81,
    # 205/55R16 tyre: 16 in rim (0.4064 m) + 2 x 0.55 x 0.205 m sidewall -> 0.632 m diameter; dynamic radius
    # ~3 % below static-unloaded: 0.307 m.
    r_wheel=0.307,
    # Single reduction gear 7.9377:1 (Nissan Leaf service manual / press kit, EM61 motor + RE1F61A reducer).
    i_gear=7.9377,
    # EM61 synchronous motor: 80 kW, 280 Nm, 10,390 rpm maximum (Nissan press kit).
    P_max=80_000.0,
    T_max=280.0,
    omega_max=10_390 * 2 * 3.141592653589793 / 60,
    # Friction brakes: ~1 g deceleration capability of a passenger car; 1.0 * m_v * g rounded: 15.7 kN (assumption).
    # Comfort deceleration is limited by the MPC cost and the DP acceleration bounds, not here.
    F_b_max=15_700.0,
    # Regenerative power limit at the shaft: assumption of 30 kW (the Leaf's regen is software-limited well below
    # the 80 kW motor rating; owners' CAN logs typically show <= ~30 kW).
    P_regen_max=30_000.0,
    # Regeneration fades out below ~5 km/h (friction brake holds the car at creep speed); assumption.
    v_regen_fade=5.0 / 3.6,
    # Auxiliary load (DC/DC for the 12 V net, pumps, controllers, lights) without heating/air conditioning: 300 W
    # (assumption; a typical value for a compact BEV with climate control off).
    P_aux=300.0,
    eta_gear=0.97,  # single-stage helical reduction, typical 97 % (assumption)
    # Loss model of motor + inverter (the standard form of Larminie & Lowry, Electric Vehicle Technology Explained:
    # P_loss = k_c T^2 + k_i w + k_w w^3 + C). Assumed coefficients: the resulting map peaks at ~94-95 % in the
    # mid-speed/mid-torque region and drops below 85 % at light load, the usual shape of a PMSM drive of this class.
    # CALIBRATION: together with c_r they are set so that the NEDC (generated from its phase table) costs ~106
    # Wh/km at the battery, in line with the 2013 Leaf's official NEDC range of 199 km on its ~21 kWh usable
    # energy (~107 Wh/km). Documented in docs/vehicle_and_references.md.
    k_copper=0.045,
    k_iron=0.5,
    k_wind=5.0e-7,
    P_const_loss=300.0,
    # Battery: 192 AESC cells in 96s2p, nominal 360 V, 24 kWh (Nissan press kit). Pack resistance 0.08 Ohm is an
    # assumption of the right order for a 96s2p pack of ~33 Ah pouch cells (~1.6 mOhm per cell).
    V_oc=360.0,
    R_int=0.08,
    E_batt=24_000.0,
)


# ----------------------------------------------------------------------------------------------------------------
# Controller tuning (pEDAS, Sec. 3.1-3.8): values the paper leaves open. pedas.constants keeps the ones it prints.


@dataclass(frozen=True)
class MpcWeights:
    """Weights and limits of one MPC the paper leaves open (docs/controller.md gives the reasoning).

    zeta1: kW/(m/s)^2 (rt: speed tracking) or kW/m^2 (cf: comfort slack e3); zeta2: kW/kN^2 (braking force);
    zeta3: kW/m^2 (stop-line slack e1); zeta4: kW/kN^2 (jerk slack e2). h_s, h_c in s, d_min in m (eq. 7),
    dFt_max in N per step (eq. 8 / constraints on F_t,k+1 - F_t,k).
    """

    zeta1: float
    zeta2: float = 0.5
    zeta3: float = 0.02
    zeta4: float = 5.0
    h_s: float = 1.0
    h_c: float = 2.5
    d_min: float = 3.0
    dFt_max: float = 700.0
    zeta_v: float = 0.0  # kW/(m/s)^2, cf only: speed matching (v_{k+1} - v_p)^2, a regulariser beyond eq. (10)


@dataclass(frozen=True)
class OsqpSettings:
    """OSQP settings used by both MPCs (tuned with `pedas-study bench mpc`; see docs/controller.md).

    :meth:`as_dict` gives the keyword arguments of ``OSQP.setup`` plus ``shift_warm_start``, which
    :class:`pedas.qp.OsqpBackend` takes out before the setup.
    """

    verbose: bool = False
    warm_starting: bool = True
    polishing: bool = False
    eps_abs: float = 2e-5
    eps_rel: float = 2e-5
    eps_prim_inf: float = 1e-5
    eps_dual_inf: float = 1e-5
    max_iter: int = 4000
    check_termination: int = 10
    adaptive_rho: bool = True
    adaptive_rho_interval: int = 25  # fixed interval: the default (0) adapts on wall-clock time, i.e. not reproducibly
    adaptive_rho_tolerance: float = 2.0  # adapt rho on a factor-2 change (default 5): ~10 fewer iterations per step
    scaling: int = 10
    shift_warm_start: bool = False  # warm start from the previous solution shifted by one sample (measured: no gain)

    def as_dict(self) -> dict:
        """The settings as a plain dict (field order), for ``OSQP.setup``."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class DaqpSettings:
    """Settings of the DAQP backend (:class:`pedas.qp.DaqpBackend`; see docs/controller.md).

    formulation: "condensed" (the states eliminated, :class:`pedas.qp.DaqpCondensedBackend`) or "regularised" (all
    variables, :class:`pedas.qp.DaqpBackend`); primal_tol: DAQP's primal feasibility tolerance (QP units: m/s, m,
    kN); iter_limit: active-set iterations per solve; residual_tol: largest violation of l <= A x <= u a solution may
    have to be used (QP units); rho: weight of the equality rows folded into the Hessian of the regularised
    formulation (H = P + rho A_eq'A_eq); bound: magnitude that replaces an infinite bound (QP units; far beyond any
    speed, distance or force of a drive).
    """

    formulation: str = "condensed"
    primal_tol: float = 1e-6
    iter_limit: int = 1000
    residual_tol: float = 1e-5
    rho: float = 1.0
    bound: float = 1e4


@dataclass(frozen=True)
class ControllerParams:
    """Every tuning value of :class:`pedas.controller.PedasController`, frozen and hashable.

    Tune with ``dataclasses.replace(CONTROLLER, blend_max_step=0.2)`` and pass it as
    ``PedasController(route, settings=...)``; the pure functions of :mod:`pedas.hud` and :mod:`pedas.greenwave`
    take the fields they use as keyword arguments defaulting to :data:`CONTROLLER`.
    """

    # ---- the two MPCs (pedas.mpc_rt, pedas.mpc_cf, pedas.mpc) ----------------------------------------------------
    # zeta1 kW/(m/s)^2, zeta2 kW/kN^2, zeta3 kW/m^2, zeta4 kW/kN^2 (docs/controller.md)
    rt_weights: MpcWeights = MpcWeights(zeta1=8.0, zeta2=0.5, zeta3=0.02, zeta4=5.0)
    # zeta1 here weighs e3 (kW/m^2); h_s, h_c s; d_min m (docs/controller.md)
    cf_weights: MpcWeights = MpcWeights(zeta1=0.3, zeta2=0.5, zeta3=0.02, zeta4=5.0, h_s=1.0, h_c=2.5, d_min=3.0,
                                        zeta_v=5.0)
    # m, the planned gap keeps this margin above d_s (constraint tightening vs solver tolerance)
    safe_backoff: float = 1.0
    # QP backend of both MPCs: "daqp" (exact active set, hot-started) or "osqp" (ADMM); docs/controller.md
    qp_backend: str = "daqp"
    # OSQP settings of both MPCs (see OsqpSettings)
    osqp: OsqpSettings = OsqpSettings()
    # DAQP settings of both MPCs (see DaqpSettings)
    daqp: DaqpSettings = DaqpSettings()

    # ---- reference speed and stop logic (pedas.controller) -------------------------------------------------------
    # m/s^2, deceleration of the stop / curve approach envelope of v_ref (early and gentle)
    a_stop: float = 1.0
    # -, the stop envelope ends 0.9 d_s,ITS before the stop line: a lagging driver still stops in the band
    stop_aim: float = 0.9
    # m/s^2, acceleration of the departure ramp of v_ref (matches the DP's a_max)
    a_depart: float = 1.0
    # m/s^2, a speed limit below the current speed is imposed no faster than this (keeps the QP feasible)
    a_reach: float = 3.0
    # m, v_DP is floored by its maximum over this look-ahead (forced DP zeros at served stops)
    cruise_look: float = 100.0
    # -, eq. (1) lower road speed where the route has v_min = 0 (town): 0.6 x limit (30 of 50 km/h)
    gw_min_fraction: float = 0.6
    # m/s^2, at yellow the vehicle goes when stopping would need more than this
    yellow_go_decel: float = 3.0
    # m/s^2, deceleration of the safe braking fallback plan
    fallback_decel: float = 3.0
    # m/s, below this the vehicle counts as standing (stop-sign dwell)
    v_stopped: float = 0.3
    # m, tolerance on the stop-line band when counting the dwell
    band_tol: float = 0.5
    # m past the stop sign after which it counts as passed (missed if the dwell was not served)
    ss_passed: float = 1.0
    # m per sample: rate at which the planned safe-distance margin may recover to safe_backoff
    psi_recovery: float = 0.2
    # samples (2 s) of rate-limited advice after a controller switch
    blend_steps: int = 10
    # m/s per sample (2 m/s^2): bound on the advised-speed change during a hand-over
    blend_max_step: float = 0.4

    # ---- HUD (pedas.hud, Sec. 3.8) -------------------------------------------------------------------------------
    # m/s, half-width of the band around v_opt with no arrow (the paper's +-2 km/h; varied by the what-if sweep)
    hud_band: float = HUD_BAND
    # m/s, |v - v_opt| at which the arrow has full length (design choice)
    arrow_full_scale: float = 10.0 * KMH
    # m, look-ahead for TL countdown / stop-sign / curve icons (design choice)
    icon_range: float = 150.0
    # s, a slow-down advice ignored this long triggers the warning tone (design choice)
    warn_delay: float = 2.0
    # m/s^2, a deceleration weaker than this does not count as following a slow-down advice
    not_decel: float = 0.3
    # m/s, below this the car stands (the drive loop's halt threshold)
    standstill: float = 0.1
    # m/s, v_opt this far above a standing car's speed means "drive off" (design choice)
    start_min: float = 0.3 * KMH

    # ---- green wave, eq. (1) (pedas.greenwave) -------------------------------------------------------------------
    # m: SPaT of a light is used from this distance on (V2I range; not printed in the paper); the controller's
    # green wave and red-light logic consider lights within this distance
    spat_range: float = 500.0
    # s: green windows considered ahead (about two signal cycles)
    gw_horizon: float = 120.0
    # m/s: in town (v_min = 0) a band below this is treated as "crawl" -> stop unavoidable
    gw_v_floor: float = 1.0
    # s: arrive at least this long after green starts / before it ends (tracking error, reaction)
    gw_margin: float = 1.5


CONTROLLER = ControllerParams()
