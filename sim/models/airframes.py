"""Airframes of the simulated vehicle: their parameters and a factory for their models.

The MAVLink/commander side owns the parameter store (seeded from `param_defaults`) and calls
`model.step()` at 250 Hz with the setpoint of the current mode; the model reads its
parameters through `ParamReader`, so a PARAM_SET takes effect without a restart.
"""

from __future__ import annotations

from typing import Protocol

from sim.lib.params import ParamReader
from sim.lib.topics import ControlSetpoint, LandingStatus, VehicleStateTruth, VtolState
from sim.models.fixed_wing import FixedWingModel
from sim.models.multicopter import MulticopterModel
from sim.models.rover import RoverModel
from sim.models.vtol import VtolModel
from sim.physics.mixer import GEOMETRIES
from sim.physics.rigid_body import GRAVITY_M_S2

AIRFRAME_NAMES = ("quad", "hexa", "octo", "plane", "vtol", "rover")

# MAV_TYPE per airframe (MAVLink enum values)
MAV_TYPE_FIXED_WING = 1
MAV_TYPE_QUADROTOR = 2
MAV_TYPE_GROUND_ROVER = 10
MAV_TYPE_HEXAROTOR = 13
MAV_TYPE_OCTOROTOR = 14
MAV_TYPE_VTOL_FIXEDROTOR = 22

__all__ = [
    "AIRFRAME_NAMES",
    "AirframeModel",
    "ParamReader",
    "StaticParams",
    "default_params",
    "make_airframe",
    "param_defaults",
]


class AirframeModel(Protocol):
    name: str
    mav_type: int
    is_vtol: bool
    truth: VehicleStateTruth
    vtol_state: VtolState
    in_fixed_wing_flight: bool
    actuator_outputs: list[float]
    power_fraction: float

    # what the land detector and the multicopter position controller share (None: no
    # multicopter, the land detector reads the state alone)
    @property
    def landing(self) -> LandingStatus | None: ...

    def step(self, dt_s: float, armed: bool, setpoint: ControlSetpoint | None) -> None: ...

    def request_transition(self, to_fixed_wing: bool, immediate: bool) -> None: ...

    def reset(self, position_ned_m: list[float], yaw_rad: float) -> None: ...


# PX4 defaults of the multicopter position, attitude and rate controllers
_MC_PARAMS: dict[str, float | int] = {
    "MPC_XY_P": 0.95,
    "MPC_Z_P": 1.0,
    "MPC_XY_VEL_P_ACC": 1.8,
    "MPC_XY_VEL_I_ACC": 0.4,
    "MPC_XY_VEL_D_ACC": 0.2,
    "MPC_Z_VEL_P_ACC": 4.0,
    "MPC_Z_VEL_I_ACC": 2.0,
    "MPC_Z_VEL_D_ACC": 0.0,
    "MPC_XY_VEL_MAX": 12.0,
    "MPC_XY_CRUISE": 5.0,
    "MPC_Z_VEL_MAX_UP": 3.0,
    "MPC_Z_VEL_MAX_DN": 1.5,
    "MPC_TKO_SPEED": 1.5,
    "MPC_TKO_RAMP_T": 3.0,
    "COM_SPOOLUP_TIME": 1.0,
    "MPC_LAND_SPEED": 0.7,
    "MPC_ACC_HOR": 3.0,
    "MPC_ACC_HOR_MAX": 5.0,
    # the controllers use the true hover thrust (SIH_MASS, SIH_T_MAX), as PX4's hover thrust
    # estimator would after converging; the parameter reports it (set per airframe below)
    "MPC_THR_HOVER": 0.5,
    "MPC_THR_MIN": 0.12,
    "MPC_THR_MAX": 1.0,
    "MPC_THR_XY_MARG": 0.3,
    "MPC_TILTMAX_AIR": 45.0,
    "MC_ROLL_P": 6.5,
    "MC_PITCH_P": 6.5,
    "MC_YAW_P": 2.8,
    "MC_YAW_WEIGHT": 0.4,
    "MC_ROLLRATE_MAX": 220.0,
    "MC_PITCHRATE_MAX": 220.0,
    "MC_YAWRATE_MAX": 200.0,
    "MC_ROLLRATE_P": 0.15,
    "MC_ROLLRATE_I": 0.2,
    "MC_ROLLRATE_D": 0.003,
    "MC_ROLLRATE_K": 1.0,
    "MC_PITCHRATE_P": 0.15,
    "MC_PITCHRATE_I": 0.2,
    "MC_PITCHRATE_D": 0.003,
    "MC_PITCHRATE_K": 1.0,
    "MC_YAWRATE_P": 0.2,
    "MC_YAWRATE_I": 0.1,
    "MC_YAWRATE_D": 0.0,
    "MC_YAWRATE_K": 1.0,
    "MC_RR_INT_LIM": 0.3,
    "MC_PR_INT_LIM": 0.3,
    "MC_YR_INT_LIM": 0.3,
}

# PX4 simulator_sih defaults (SIH quadrotor)
_SIH_PARAMS: dict[str, float | int] = {
    "SIH_MASS": 1.0,
    "SIH_IXX": 0.025,
    "SIH_IYY": 0.025,
    "SIH_IZZ": 0.030,
    "SIH_T_MAX": 5.0,
    "SIH_Q_MAX": 0.1,
    "SIH_L_ROLL": 0.2,
    "SIH_L_PITCH": 0.2,
    "SIH_KDV": 1.0,
    "SIH_KDW": 0.025,
    "SIH_T_TAU": 0.05,
}

# Fixed-wing guidance, TECS-like height/speed and attitude/rate control (PX4 names)
_FW_PARAMS: dict[str, float | int] = {
    "FW_AIRSPD_MIN": 10.0,
    "FW_AIRSPD_TRIM": 15.0,
    "FW_AIRSPD_MAX": 20.0,
    "NAV_LOITER_RAD": 80.0,
    "FW_R_LIM": 50.0,
    "FW_P_LIM_MAX": 30.0,
    "FW_P_LIM_MIN": -30.0,
    "FW_R_TC": 0.4,
    "FW_P_TC": 0.4,
    "FW_R_RMAX": 70.0,
    "FW_P_RMAX_POS": 60.0,
    "FW_Y_RMAX": 50.0,
    "FW_RR_P": 0.05,
    "FW_RR_I": 0.1,
    "FW_RR_FF": 0.5,
    "FW_PR_P": 0.08,
    "FW_PR_I": 0.1,
    "FW_PR_FF": 0.5,
    "FW_YR_P": 0.05,
    "FW_YR_I": 0.1,
    "FW_YR_FF": 0.3,
    "FW_T_CLMB_MAX": 5.0,
    "FW_T_SINK_MAX": 5.0,
    "FW_THR_TRIM": 0.35,
    "FW_THR_MAX": 1.0,
    "FW_THR_MIN": 0.0,
    "FW_THR_IDLE": 0.0,
    "FW_LND_FLALT": 0.5,
    "FW_LND_FL_PMIN": 2.5,
}

# PX4's SIH airplane (10041_sihsim_airplane): 0.3 kg, SIH's wing and a SIH_T_MAX pusher
_PLANE_PARAMS: dict[str, float | int] = {
    "SIH_MASS": 0.3,
    "SIH_IXX": 0.00402,
    "SIH_IYY": 0.0144,
    "SIH_IZZ": 0.0177,
    "SIH_KDV": 0.2,
    "SIH_T_MAX": 6.0,
}

# PX4's SIH standard VTOL (10043_sihsim_standard_vtol): 0.2 kg on four 2 N rotors, SIH's
# wing and a pusher of 2 × SIH_T_MAX
_VTOL_PARAMS: dict[str, float | int] = {
    "SIH_MASS": 0.2,
    "SIH_IXX": 0.00354,
    "SIH_IYY": 0.000625,
    "SIH_IZZ": 0.003,
    "SIH_KDV": 0.2,
    "SIH_T_MAX": 2.0,
    "SIH_Q_MAX": 0.0165,
    "SIH_L_ROLL": 0.2,
    # a winged airframe hovering is no racer: PX4's VTOL airframes lower the MC speed
    "MPC_XY_VEL_MAX": 8.0,
    "FW_AIRSPD_MIN": 7.0,
    "FW_AIRSPD_TRIM": 10.0,
    "FW_AIRSPD_MAX": 12.0,
    "FW_THR_TRIM": 0.6,
    "FW_USE_AIRSPD": 1,
    "VT_ARSP_TRANS": 10.0,
    "VT_TRANS_MIN_TM": 2.0,
    "VT_F_TR_OL_TM": 6.0,
    "VT_TRANS_TIMEOUT": 15.0,
    "VT_PSHER_SLEW": 0.33,
    "VT_F_TRANS_THR": 1.0,
    "VT_B_TRANS_DUR": 10.0,
    "VT_B_TRANS_RAMP": 3.0,
}

# Differential rover (PX4 rover_pos_control / rover_differential names)
_ROVER_PARAMS: dict[str, float | int] = {
    "GND_SPEED_MAX": 10.0,
    "GND_SPEED_TRIM": 3.0,
    "RO_ACCEL_LIM": 2.0,
    "RO_DECEL_LIM": 3.0,
    "RO_YAW_RATE_LIM": 90.0,
    "RD_WHEEL_TRACK": 0.3,
}

_MULTICOPTERS: dict[str, tuple[int, str, float]] = {
    # name: (MAV_TYPE, mixer geometry, mass in kg so that hover thrust stays ≈ 0.5)
    "quad": (MAV_TYPE_QUADROTOR, "4x", 1.0),
    "hexa": (MAV_TYPE_HEXAROTOR, "6x", 1.5),
    "octo": (MAV_TYPE_OCTOROTOR, "8x", 2.0),
}


def _hover_thrust(mass_kg: float, rotor_count: int) -> float:
    return round(mass_kg * GRAVITY_M_S2 / (rotor_count * float(_SIH_PARAMS["SIH_T_MAX"])), 3)


def _multicopter_params(mass_kg: float, rotor_count: int) -> dict[str, float | int]:
    """The SIH quad scaled to a heavier frame: same rotors, inertia growing with mass."""
    scale = mass_kg / float(_SIH_PARAMS["SIH_MASS"])
    return {
        "SIH_MASS": mass_kg,
        # PX4's default; the controllers fly with the true hover thrust (hover_thrust())
        "MPC_THR_HOVER": 0.5 if rotor_count == 4 else _hover_thrust(mass_kg, rotor_count),
        **{name: float(_SIH_PARAMS[name]) * scale for name in ("SIH_IXX", "SIH_IYY", "SIH_IZZ")},
    }


# Later tables override earlier ones
_PARAM_TABLES: dict[str, tuple[dict[str, float | int], ...]] = {
    **{
        name: (_SIH_PARAMS, _MC_PARAMS, _multicopter_params(mass_kg, len(GEOMETRIES[geometry])))
        for name, (_, geometry, mass_kg) in _MULTICOPTERS.items()
    },
    "plane": (_SIH_PARAMS, _FW_PARAMS, _PLANE_PARAMS),
    "vtol": (
        _SIH_PARAMS,
        _MC_PARAMS,
        _FW_PARAMS,
        _VTOL_PARAMS,
        {"MPC_THR_HOVER": 0.5},
    ),
    "rover": (_ROVER_PARAMS,),
}


def param_defaults(airframe: str) -> dict[str, float | int]:
    """Every parameter the physics and controllers of `airframe` read, with PX4 defaults
    (airframe-specific values where PX4's SIH airframes have no equivalent).

    A Python int means an INT32 parameter, a float REAL32.
    """
    if airframe not in _PARAM_TABLES:
        raise ValueError(f"unknown airframe {airframe!r}; known: {', '.join(AIRFRAME_NAMES)}")
    params: dict[str, float | int] = {}
    for table in _PARAM_TABLES[airframe]:
        params.update(table)
    return params


def make_airframe(name: str, params: ParamReader) -> AirframeModel:
    if name in _MULTICOPTERS:
        mav_type, geometry, _ = _MULTICOPTERS[name]
        return MulticopterModel(name, mav_type, geometry, params)
    if name == "plane":
        return FixedWingModel(params)
    if name == "vtol":
        return VtolModel(params)
    if name == "rover":
        return RoverModel(params)
    raise ValueError(f"unknown airframe {name!r}; known: {', '.join(AIRFRAME_NAMES)}")


class StaticParams:
    """A ParamReader over a plain dict, for running a model without the parameter store."""

    def __init__(self, values: dict[str, float | int]) -> None:
        self.values = dict(values)

    def get(self, name: str) -> float:
        return float(self.values[name])


def default_params(airframe: str) -> StaticParams:
    return StaticParams(param_defaults(airframe))
