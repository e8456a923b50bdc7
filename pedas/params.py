"""Vehicle parameters the paper leaves open: the Nissan Leaf (ZE0/AZE0, 2013-2017, 24/30 kWh) host vehicle.

The paper names the Leaf as host vehicle and takes its vehicle and battery models from Lin et al. (2014) without
printing the numbers. Every value below therefore comes from public manufacturer data or is a documented
engineering assumption; the source is written next to each value and collected in docs/vehicle_and_references.md.
Constants the paper prints (DT, N, alphas, ...) live in `pedas.constants`, not here.
"""
from __future__ import annotations

from dataclasses import dataclass


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
    # EM61 synchronous motor: 80 kW, 280 Nm, 10,390 rpm maximum (Nissan press kit); the issue fixes 80 kW/280 Nm.
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
