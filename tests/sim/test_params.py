"""Parameters: PX4 defaults, airframe overrides, bytewise encoding, the PARAM protocol."""

from __future__ import annotations

import math
import struct

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.lib.params import (
    ParamStore,
    decode_param_value,
    encode_param_value,
    sitl_family_values,
)
from sim.models.airframes import param_defaults
from tests.sim.conftest import Harness


def test_int32_parameter_bits_travel_inside_the_float_field() -> None:
    wire = encode_param_value(1, mavlink.MAV_PARAM_TYPE_INT32)
    assert struct.pack("<f", wire) == struct.pack("<i", 1)
    assert 0 < wire < 1e-44  # what a client that reads it as a float sees (1.4e-45)
    assert decode_param_value(wire, mavlink.MAV_PARAM_TYPE_INT32) == 1
    assert decode_param_value(encode_param_value(-7, mavlink.MAV_PARAM_TYPE_INT32), 6) == -7


def test_real32_parameter_is_sent_as_its_value() -> None:
    assert encode_param_value(2.5, mavlink.MAV_PARAM_TYPE_REAL32) == 2.5


def test_airframe_specific_defaults_override_px4_defaults() -> None:
    quad = ParamStore.for_airframe("quad", {})
    vtol = ParamStore.for_airframe("vtol", {})
    assert (quad.get("MIS_TAKEOFF_ALT"), quad.get("RTL_RETURN_ALT")) == (2.5, 30.0)
    assert (vtol.get("MIS_TAKEOFF_ALT"), vtol.get("RTL_RETURN_ALT")) == (20.0, 60.0)
    assert quad.get("COM_OF_LOSS_T") == 1.0
    assert quad.param_type("COM_OBL_RC_ACT") == mavlink.MAV_PARAM_TYPE_INT32
    assert quad.param_type("COM_OF_LOSS_T") == mavlink.MAV_PARAM_TYPE_REAL32


def test_airframe_param_defaults_are_merged_into_the_store() -> None:
    store = ParamStore.for_airframe("quad", {"SIH_MASS": 1.0, "MC_ROLL_P": 6.5})
    assert store.get("SIH_MASS") == 1.0
    assert "MC_ROLL_P" in store


def test_the_plane_has_no_multicopter_parameters_but_its_code_reads_px4_defaults() -> None:
    # PX4's airplane runs no mc_pos_control nor multicopter land detector: of the MPC_ and
    # LNDMC_ families it has only the few MPC_ the shared trajectory code reads
    plane = ParamStore.for_airframe("plane", param_defaults("plane"))
    px4_airplane = sitl_family_values("plane")
    multicopter = [name for name in plane if name.startswith(("MPC_", "LNDMC_"))]
    assert multicopter
    assert all(plane.value(name) == px4_airplane[name] for name in multicopter)
    assert "MPC_LAND_SPEED" not in plane
    assert "LNDMC_TRIG_TIME" not in plane
    assert plane.get("MPC_LAND_SPEED") == 0.7
    assert plane.get("LNDMC_TRIG_TIME") == 1.0
    # SIH's airplane: no parameter of the sim's own, PX4's SIH_* values
    assert "SIH_F_T_MAX" not in plane
    assert (plane.get("SIH_MASS"), plane.get("SIH_T_MAX"), plane.get("SIH_KDV")) == (0.3, 6.0, 0.2)
    vtol = ParamStore.for_airframe("vtol", param_defaults("vtol"))
    assert "MPC_LAND_SPEED" in vtol
    assert (vtol.get("SIH_MASS"), vtol.get("SIH_T_MAX"), vtol.get("SIH_Q_MAX")) == (
        0.2, 2.0, 0.0165)


def test_param_request_list_sends_every_parameter_with_index_and_count(harness: Harness) -> None:
    harness.deliver(mavlink.MAVLink_param_request_list_message(1, 1))
    values = harness.api.of_type("PARAM_VALUE")
    count = len(harness.vehicle.params)
    assert len(values) == count
    assert {v.param_count for v in values} == {count}
    assert sorted(v.param_index for v in values) == list(range(count))


def test_param_read_by_name_and_by_index(harness: Harness) -> None:
    harness.deliver(mavlink.MAVLink_param_request_read_message(1, 1, b"COM_RC_IN_MODE", -1))
    (value,) = harness.api.of_type("PARAM_VALUE")
    assert value.param_type == mavlink.MAV_PARAM_TYPE_INT32
    # PX4 SITL's startup files set COM_RC_IN_MODE 1 (joystick only)
    assert decode_param_value(value.param_value, value.param_type) == 1
    harness.api.clear()
    harness.deliver(mavlink.MAVLink_param_request_read_message(1, 1, b"", value.param_index))
    assert harness.api.of_type("PARAM_VALUE")[0].param_id == "COM_RC_IN_MODE"


def test_reading_an_unknown_parameter_gets_no_answer(harness: Harness) -> None:
    harness.deliver(mavlink.MAVLink_param_request_read_message(1, 1, b"NO_SUCH_PARAM", -1))
    harness.deliver(mavlink.MAVLink_param_set_message(1, 1, b"NO_SUCH_PARAM", 1.0, 9))
    assert harness.api.of_type("PARAM_VALUE") == []


def test_param_set_stores_decodes_bytewise_and_echoes(harness: Harness) -> None:
    wire = encode_param_value(4, mavlink.MAV_PARAM_TYPE_INT32)
    harness.deliver(mavlink.MAVLink_param_set_message(1, 1, b"COM_OBL_RC_ACT", wire, 6))
    assert harness.vehicle.params.value("COM_OBL_RC_ACT") == 4
    echoes = [m for m in harness.api.of_type("PARAM_VALUE") if m.param_id == "COM_OBL_RC_ACT"]
    assert echoes
    assert decode_param_value(echoes[-1].param_value, 6) == 4
    assert harness.gcs.of_type("PARAM_VALUE"), "PX4 announces the change on every link"


def test_param_set_for_another_system_is_ignored(harness: Harness) -> None:
    harness.deliver(mavlink.MAVLink_param_set_message(7, 1, b"MIS_TAKEOFF_ALT", 9.0, 9))
    assert harness.vehicle.params.get("MIS_TAKEOFF_ALT") == 2.5
    assert not math.isnan(harness.vehicle.params.get("MIS_TAKEOFF_ALT"))


def test_px4_param_variables_set_each_parameter_in_its_own_type() -> None:
    params = ParamStore({"COM_DISARM_PRFLT": 10.0, "NAV_DLL_ACT": 0, "MAV_SYS_ID": 1})
    problems = params.set_from_environment({
        "PX4_PARAM_COM_DISARM_PRFLT": "80.5", "PX4_PARAM_NAV_DLL_ACT": "2", "HOME": "/root",
        "PX4_PARAM_LOST": "1", "PX4_PARAM_MAV_SYS_ID": "7"})  # fmt: skip
    assert params.value("COM_DISARM_PRFLT") == 80.5
    assert params.value("NAV_DLL_ACT") == 2
    assert isinstance(params.value("NAV_DLL_ACT"), int)
    assert params.value("MAV_SYS_ID") == 1
    assert problems == [
        "PX4_PARAM_LOST: this vehicle has no parameter LOST",
        "PX4_PARAM_MAV_SYS_ID: the system id follows the instance (--instance)",
    ]


@pytest.mark.parametrize("text", ["2.5", "two", "nan", ""])
def test_a_px4_param_variable_that_is_no_number_of_the_type_is_said_and_left(text: str) -> None:
    params = ParamStore({"NAV_DLL_ACT": 0, "MPC_XY_CRUISE": 5.0})
    variable = "PX4_PARAM_NAV_DLL_ACT" if text == "2.5" else "PX4_PARAM_MPC_XY_CRUISE"
    problems = params.set_from_environment({variable: text})
    assert len(problems) == 1
    assert problems[0].startswith(variable)
    assert (params.value("NAV_DLL_ACT"), params.value("MPC_XY_CRUISE")) == (0, 5.0)
