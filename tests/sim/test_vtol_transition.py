"""Standard VTOL: transition logic and timings (PX4_NOTES "VTOL"), FW circling, quadchute."""

from __future__ import annotations

import math
import random

import pytest

from sim.lib.quat import rotate_ned_to_body
from sim.lib.topics import TrajectorySetpoint, VtolState
from sim.models.airframes import AirframeModel, StaticParams, default_params, make_airframe
from sim.models.sim_run import PHYSICS_DT_S, fly, fly_peak
from sim.models.vtol import VtolTransition

HOLD = TrajectorySetpoint(position_ned_m=[0.0, 0.0, -30.0])


def _hovering_vtol(params: StaticParams | None = None) -> AirframeModel:
    vtol = make_airframe("vtol", params or default_params("vtol"))
    vtol.reset([0.0, 0.0, 0.0], 0.0)
    fly(vtol, HOLD, 14.0)
    assert vtol.vtol_state == VtolState.MC
    return vtol


def _states_until(
    vtol: AirframeModel, final: VtolState, limit_s: float
) -> tuple[list[VtolState], float]:
    """Distinct vtol_state values seen while flying HOLD, and the time `final` was reached."""
    seen = [vtol.vtol_state]

    def reached() -> bool:
        if vtol.vtol_state != seen[-1]:
            seen.append(vtol.vtol_state)
        return vtol.vtol_state == final

    elapsed = fly(vtol, HOLD, limit_s, until=reached)
    assert elapsed is not None, f"never reached {final.name}; saw {[s.name for s in seen]}"
    return seen, elapsed


def _state_of(vtol: AirframeModel) -> VtolState:
    return vtol.vtol_state


def _forward_speed(vtol: AirframeModel) -> float:
    return rotate_ned_to_body(vtol.truth.q_wxyz, vtol.truth.velocity_ned_m_s)[0]


def test_vtol_identity() -> None:
    vtol = make_airframe("vtol", default_params("vtol"))
    assert vtol.is_vtol
    assert vtol.mav_type == 22
    assert vtol.vtol_state == VtolState.MC
    assert not vtol.in_fixed_wing_flight
    assert make_airframe("quad", default_params("quad")).vtol_state == VtolState.UNDEFINED


def test_front_transition_reaches_fixed_wing_like_px4_sih() -> None:
    vtol = _hovering_vtol()
    vtol.request_transition(to_fixed_wing=True, immediate=False)
    assert vtol.vtol_state == VtolState.TRANSITION_TO_FW
    seen, elapsed = _states_until(vtol, VtolState.FW, 8.0)
    assert seen == [VtolState.TRANSITION_TO_FW, VtolState.FW]
    # PX4 v1.16 SIH: 2.7–3.9 s; never before VT_TRANS_MIN_TM
    assert 2.0 <= elapsed <= 6.0
    assert vtol.truth.airspeed_m_s >= 10.0
    assert vtol.in_fixed_wing_flight
    assert abs(vtol.truth.position_ned_m[2] + 30.0) < 2.0


def test_fixed_wing_vtol_circles_the_target_holding_altitude() -> None:
    vtol = _hovering_vtol()
    vtol.request_transition(to_fixed_wing=True, immediate=False)
    fly(vtol, HOLD, 60.0)
    assert vtol.vtol_state == VtolState.FW
    radius = math.hypot(*vtol.truth.position_ned_m[:2])
    assert radius == pytest.approx(80.0, abs=3.0)
    worst_alt = fly_peak(vtol, HOLD, 30.0, lambda: abs(vtol.truth.position_ned_m[2] + 30.0))
    assert worst_alt < 1.0
    assert 7.0 <= vtol.truth.airspeed_m_s <= 11.0
    # the lift rotors are off in fixed-wing flight; the pusher flies
    assert vtol.actuator_outputs[:4] == [0.0, 0.0, 0.0, 0.0]
    assert vtol.actuator_outputs[4] > 0.1


def test_back_transition_returns_to_multicopter() -> None:
    vtol = _hovering_vtol()
    vtol.request_transition(to_fixed_wing=True, immediate=False)
    fly(vtol, HOLD, 15.0)
    assert vtol.vtol_state == VtolState.FW
    vtol.request_transition(to_fixed_wing=False, immediate=False)
    assert _state_of(vtol) == VtolState.TRANSITION_TO_MC
    seen, elapsed = _states_until(vtol, VtolState.MC, 10.0)
    assert seen == [VtolState.TRANSITION_TO_MC, VtolState.MC]
    # ends on MPC_XY_CRUISE forward speed long before VT_B_TRANS_DUR (PX4 SIH: ≈ 0.65 s)
    assert elapsed < 3.0
    assert _forward_speed(vtol) < 5.0
    # then flies back from its loiter circle as a multicopter; SIH's 0.2 kg VTOL does so at
    # about 4 m/s (pitched forward, its wing pushes down and its fin yaws it)
    fly(vtol, HOLD, 40.0)
    assert math.dist(vtol.truth.position_ned_m, HOLD.position_ned_m) < 1.0


def test_unreachable_transition_airspeed_quadchutes_back_to_mc() -> None:
    params = default_params("vtol")
    params.values["VT_ARSP_TRANS"] = 60.0
    params.values["VT_TRANS_TIMEOUT"] = 6.0
    vtol = _hovering_vtol(params)
    vtol.request_transition(to_fixed_wing=True, immediate=False)
    seen, elapsed = _states_until(vtol, VtolState.MC, 10.0)
    assert seen == [VtolState.TRANSITION_TO_FW, VtolState.MC]
    assert elapsed == pytest.approx(6.0, abs=0.05)
    assert not vtol.in_fixed_wing_flight
    fly(vtol, HOLD, 2.0)
    assert all(math.isfinite(v) for v in vtol.truth.position_ned_m)


def test_no_transition_while_on_the_ground() -> None:
    vtol = make_airframe("vtol", default_params("vtol"))
    vtol.reset([0.0, 0.0, 0.0], 0.0)
    vtol.request_transition(to_fixed_wing=True, immediate=False)
    assert vtol.vtol_state == VtolState.MC


def test_immediate_transitions_switch_at_once() -> None:
    vtol = _hovering_vtol()
    vtol.request_transition(to_fixed_wing=True, immediate=True)
    assert vtol.vtol_state == VtolState.FW
    vtol.request_transition(to_fixed_wing=False, immediate=True)
    assert _state_of(vtol) == VtolState.MC


def test_back_request_during_front_transition_abandons_it() -> None:
    vtol = _hovering_vtol()
    vtol.request_transition(to_fixed_wing=True, immediate=False)
    fly(vtol, HOLD, 1.0)
    vtol.request_transition(to_fixed_wing=False, immediate=False)
    assert vtol.vtol_state == VtolState.MC
    fly(vtol, HOLD, PHYSICS_DT_S)
    assert vtol.actuator_outputs[4] == 0.0


def front_transition_time_s(params: StaticParams, airspeed_m_s: float) -> float:
    """How long the front transition logic takes at a steady airspeed (and ground speed)."""
    logic = VtolTransition(params)
    logic.request(to_fixed_wing=True, immediate=False, airborne=True)
    dt = 0.01
    elapsed = 0.0
    speeds = {"airspeed_m_s": airspeed_m_s, "forward_speed_m_s": airspeed_m_s}
    while logic.update(dt, **speeds) != VtolState.FW:
        elapsed += dt
        assert elapsed < 10.0
    return elapsed


def test_transition_logic_waits_vt_trans_min_tm_even_when_fast() -> None:
    elapsed = front_transition_time_s(default_params("vtol"), airspeed_m_s=20.0)
    assert elapsed == pytest.approx(2.0, abs=0.02)


def test_without_airspeed_sensor_the_transition_ends_after_vt_f_tr_ol_tm() -> None:
    params = default_params("vtol")
    params.values["FW_USE_AIRSPD"] = 0
    elapsed = front_transition_time_s(params, airspeed_m_s=0.0)
    assert elapsed == pytest.approx(6.0, abs=0.02)


def test_pusher_ramps_at_vt_psher_slew_up_to_vt_f_trans_thr() -> None:
    params = default_params("vtol")
    params.values["VT_F_TRANS_THR"] = 0.8
    logic = VtolTransition(params)
    logic.request(to_fixed_wing=True, immediate=False, airborne=True)
    for _ in range(100):
        logic.update(0.01, airspeed_m_s=0.0, forward_speed_m_s=0.0)
    assert logic.pusher_throttle == pytest.approx(0.33, abs=1e-6)
    for _ in range(300):
        logic.update(0.01, airspeed_m_s=0.0, forward_speed_m_s=0.0)
    assert logic.pusher_throttle == pytest.approx(0.8)


def _back_transition(params: StaticParams) -> VtolTransition:
    """A VTOL in fixed-wing flight that has just been asked back to multicopter."""
    logic = VtolTransition(params)
    logic.request(to_fixed_wing=True, immediate=True, airborne=True)
    logic.request(to_fixed_wing=False, immediate=False, airborne=True)
    return logic


def test_back_transition_ends_after_vt_b_trans_dur_if_still_fast() -> None:
    params = default_params("vtol")
    params.values["VT_B_TRANS_DUR"] = 1.5
    logic = _back_transition(params)
    elapsed = 0.0
    while logic.update(0.01, airspeed_m_s=15.0, forward_speed_m_s=15.0) != VtolState.MC:
        elapsed += 0.01
        assert elapsed < 5.0
    assert elapsed == pytest.approx(1.5, abs=0.02)


def test_vtol_never_produces_nan_under_random_setpoints_and_transitions() -> None:
    rng = random.Random(3)
    vtol = _hovering_vtol()
    for _ in range(30):
        if rng.random() < 0.3:
            vtol.request_transition(to_fixed_wing=rng.random() < 0.5, immediate=rng.random() < 0.3)
        target = [rng.uniform(-200, 200), rng.uniform(-200, 200), rng.uniform(-60, -10)]
        fly(vtol, TrajectorySetpoint(position_ned_m=target), 1.0, armed=rng.random() > 0.05)
        t = vtol.truth
        state = [*t.position_ned_m, *t.velocity_ned_m_s, *t.q_wxyz, t.airspeed_m_s]
        assert all(math.isfinite(v) for v in state)
        assert t.position_ned_m[2] <= 0.0
        assert all(math.isfinite(u) for u in vtol.actuator_outputs)
        assert vtol.in_fixed_wing_flight == (vtol.vtol_state == VtolState.FW)


def _back_transition_from_fixed_wing(params: StaticParams) -> tuple[float, float, float]:
    """Back transition from fixed-wing cruise: (time to MC, and the forward speed each physics
    step saw on its last two ticks in TRANSITION_TO_MC; a step decides on the state it starts
    from)."""
    vtol = _hovering_vtol(params)
    vtol.request_transition(to_fixed_wing=True, immediate=False)
    fly(vtol, HOLD, 15.0)
    assert vtol.vtol_state == VtolState.FW
    vtol.request_transition(to_fixed_wing=False, immediate=False)
    before = [_forward_speed(vtol)]

    def switched() -> bool:
        if vtol.vtol_state == VtolState.MC:
            return True
        before.append(_forward_speed(vtol))
        return False

    elapsed = fly(vtol, HOLD, 10.0, until=switched)
    assert elapsed is not None
    return elapsed, before[-2], before[-1]


def test_back_transition_ends_on_the_first_tick_below_mpc_xy_cruise() -> None:
    # PX4 standard.cpp: the forward (body x) speed below MPC_XY_CRUISE ends it, long before
    # VT_B_TRANS_DUR (10 s); a faster MPC_XY_CRUISE ends it sooner
    cruise = default_params("vtol").get("MPC_XY_CRUISE")
    assert cruise == 5.0
    elapsed, speed_before, speed_at = _back_transition_from_fixed_wing(default_params("vtol"))
    assert speed_before >= cruise > speed_at
    assert elapsed < 3.0
    faster = default_params("vtol")
    faster.values["MPC_XY_CRUISE"] = 8.0
    elapsed_8, speed_before_8, speed_at_8 = _back_transition_from_fixed_wing(faster)
    assert speed_before_8 >= 8.0 > speed_at_8
    assert elapsed_8 < 0.7 * elapsed


def test_back_transition_ends_at_once_when_disarmed_or_landed() -> None:
    # PX4 can_transition_on_ground(): !armed || landed, whatever the speed and the time
    logic = _back_transition(default_params("vtol"))
    fast = {"airspeed_m_s": 15.0, "forward_speed_m_s": 15.0}
    assert logic.update(0.01, **fast) == VtolState.TRANSITION_TO_MC
    assert logic.update(0.01, **fast, disarmed_or_landed=True) == VtolState.MC


def test_back_transition_time_limit_is_strictly_after_vt_b_trans_dur() -> None:
    params = default_params("vtol")
    params.values["VT_B_TRANS_DUR"] = 0.5
    logic = _back_transition(params)
    fast = {"airspeed_m_s": 15.0, "forward_speed_m_s": 15.0}
    assert logic.update(0.5, **fast) == VtolState.TRANSITION_TO_MC
    assert logic.update(0.01, **fast) == VtolState.MC
