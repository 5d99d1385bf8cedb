"""Parameters: PX4's bytewise codec and the read / list / set protocol."""

from __future__ import annotations

import asyncio
import struct
from typing import cast

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.core.requests import Requester
from server.link.plugins.params import (
    MAV_PARAM_TYPE_INT8,
    MAV_PARAM_TYPE_INT32,
    MAV_PARAM_TYPE_REAL32,
    MAV_PARAM_TYPE_UINT8,
    MAV_PARAM_TYPE_UINT16,
    ParamClient,
    ParamError,
    ParamUnknown,
    decode_param_value,
    encode_param_value,
)
from tests.link.conftest import ScriptedPeer, ScriptedSession


def test_int32_parameter_of_one_travels_as_the_float_with_the_same_bits() -> None:
    wire = encode_param_value(1, MAV_PARAM_TYPE_INT32)

    assert wire == pytest.approx(1.4e-45, rel=0.01)
    assert struct.pack("<f", wire) == struct.pack("<i", 1)
    assert decode_param_value(wire, MAV_PARAM_TYPE_INT32) == 1


@pytest.mark.parametrize(
    ("value", "param_type"),
    [(-7, MAV_PARAM_TYPE_INT32), (2_000_000_000, MAV_PARAM_TYPE_INT32),
     (255, MAV_PARAM_TYPE_UINT8), (-128, MAV_PARAM_TYPE_INT8), (40000, MAV_PARAM_TYPE_UINT16)],
)  # fmt: skip
def test_integer_types_round_trip_bytewise(value: int, param_type: int) -> None:
    decoded = decode_param_value(encode_param_value(value, param_type), param_type)

    assert decoded == value
    assert isinstance(decoded, int)


def test_real32_is_carried_as_is() -> None:
    assert encode_param_value(2.5, MAV_PARAM_TYPE_REAL32) == 2.5
    assert decode_param_value(2.5, MAV_PARAM_TYPE_REAL32) == 2.5


def test_fractional_value_for_an_integer_parameter_is_refused() -> None:
    with pytest.raises(ParamError):
        encode_param_value(1.5, MAV_PARAM_TYPE_INT32)


class _ParamServer:
    """PX4's parameter behaviour: silent on unknown names, bytewise ints, an echo on set."""

    def __init__(self, peer: ScriptedPeer, params: dict[str, tuple[float | int, int]]) -> None:
        self.peer = peer
        self.params = params
        self.names = list(params)
        self.drop_in_list: set[int] = set()
        self.clamp: dict[str, float | int] = {}
        peer.on_message = self.handle

    def send_value(self, name: str) -> None:
        value, ptype = self.params[name]
        self.peer.send(mavlink.MAVLink_param_value_message(
            name.encode(), encode_param_value(value, ptype), ptype, len(self.names),
            self.names.index(name)))  # fmt: skip

    def handle(self, msg: mavlink.MAVLink_message) -> None:
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_READ":
            name = msg.param_id if msg.param_index < 0 else self.names[msg.param_index]
            if name in self.params:
                self.send_value(name)
        elif kind == "PARAM_REQUEST_LIST":
            for i, name in enumerate(self.names):
                if i not in self.drop_in_list:
                    self.send_value(name)
        elif kind == "PARAM_SET" and msg.param_id in self.params:
            _, ptype = self.params[msg.param_id]
            value = decode_param_value(msg.param_value, msg.param_type)
            self.params[msg.param_id] = (self.clamp.get(msg.param_id, value), ptype)
            self.send_value(msg.param_id)


def _px4_params(peer: ScriptedPeer) -> _ParamServer:
    return _ParamServer(peer, {
        "COM_RC_IN_MODE": (1, MAV_PARAM_TYPE_INT32),
        "MIS_TAKEOFF_ALT": (2.5, MAV_PARAM_TYPE_REAL32),
        "NAV_DLL_ACT": (0, MAV_PARAM_TYPE_INT32),
        "MPC_XY_CRUISE": (5.0, MAV_PARAM_TYPE_REAL32),
    })  # fmt: skip


async def test_get_decodes_an_int_parameter_by_its_type(scripted: ScriptedSession) -> None:
    _px4_params(scripted.peer)

    assert await scripted.vehicle.get_param("COM_RC_IN_MODE") == 1
    assert await scripted.vehicle.get_param("MIS_TAKEOFF_ALT") == pytest.approx(2.5)


async def test_unknown_parameter_is_told_by_the_list_then_at_once(
    scripted: ScriptedSession,
) -> None:
    _px4_params(scripted.peer)

    with pytest.raises(ParamUnknown) as unknown:
        await scripted.vehicle.get_param("NO_SUCH_PARAM")
    assert unknown.value.name == "NO_SUCH_PARAM"
    # asked by name with retries, then the whole list said the vehicle has no such name
    assert len(scripted.peer.messages("PARAM_REQUEST_READ")) == 4
    assert len(scripted.peer.messages("PARAM_REQUEST_LIST")) == 1
    # the list is known now: another unknown name is refused without asking
    with pytest.raises(ParamUnknown):
        await scripted.vehicle.get_param("NOR_THIS_ONE")
    assert len(scripted.peer.messages("PARAM_REQUEST_READ")) == 4
    assert await scripted.vehicle.get_param("NAV_DLL_ACT") == 0


async def test_a_vehicle_silent_on_the_list_too_times_out(scripted: ScriptedSession) -> None:
    server = _px4_params(scripted.peer)
    server.names = []  # answers nothing to a list
    server.params = {}

    with pytest.raises(TimeoutError):
        await scripted.vehicle.get_param("NO_SUCH_PARAM")
    assert len(scripted.peer.messages("PARAM_REQUEST_READ")) == 4


async def test_get_many_returns_each_value(scripted: ScriptedSession) -> None:
    _px4_params(scripted.peer)

    values = await scripted.vehicle.get_params(["NAV_DLL_ACT", "MPC_XY_CRUISE"])

    assert values == {"NAV_DLL_ACT": 0, "MPC_XY_CRUISE": 5.0}


async def test_list_rerequests_missing_indices_by_index(scripted: ScriptedSession) -> None:
    server = _px4_params(scripted.peer)
    server.drop_in_list = {2}

    values = await scripted.vehicle.get_params()

    assert values == {
        "COM_RC_IN_MODE": 1,
        "MIS_TAKEOFF_ALT": 2.5,
        "NAV_DLL_ACT": 0,
        "MPC_XY_CRUISE": 5.0,
    }
    by_index = [m.param_index for m in scripted.peer.messages("PARAM_REQUEST_READ")]
    assert by_index == [2]


async def test_set_sends_bytewise_and_checks_the_echo(scripted: ScriptedSession) -> None:
    server = _px4_params(scripted.peer)

    assert await scripted.vehicle.set_param("COM_RC_IN_MODE", 4) == 4

    (sent,) = scripted.peer.messages("PARAM_SET")
    assert struct.pack("<f", sent.param_value) == struct.pack("<i", 4)
    assert sent.param_type == MAV_PARAM_TYPE_INT32
    assert server.params["COM_RC_IN_MODE"] == (4, MAV_PARAM_TYPE_INT32)
    assert scripted.vehicle.params.cache["COM_RC_IN_MODE"].value == 4


async def test_set_whose_echo_differs_is_an_error(scripted: ScriptedSession) -> None:
    server = _px4_params(scripted.peer)
    server.clamp["MPC_XY_CRUISE"] = 20.0

    with pytest.raises(ParamError, match="the vehicle answered 20"):
        await scripted.vehicle.set_param("MPC_XY_CRUISE", 50.0)


async def test_an_older_value_arriving_before_the_echo_is_not_the_answer(
    scripted: ScriptedSession,
) -> None:
    """A PARAM_VALUE still on its way when the set goes out (a read's answer, the list, the
    vehicle's report of an earlier change) carries the old value: the set is not refused for
    it, and the value the vehicle echoes is the answer."""
    server = _px4_params(scripted.peer)
    echo = server.handle

    def stale_first(msg: mavlink.MAVLink_message) -> None:
        if msg.get_type() == "PARAM_SET" and not scripted.peer.messages("PARAM_SET")[1:]:
            server.send_value(msg.param_id)  # the old value, still on its way
            asyncio.get_running_loop().call_later(0.05, echo, msg)
            return
        echo(msg)

    scripted.peer.on_message = stale_first
    assert await scripted.vehicle.set_param("MIS_TAKEOFF_ALT", 3.5) == 3.5
    assert server.params["MIS_TAKEOFF_ALT"] == (3.5, MAV_PARAM_TYPE_REAL32)
    assert scripted.vehicle.params.cache["MIS_TAKEOFF_ALT"].value == 3.5


async def test_a_late_echo_behind_older_answers_is_the_answer_not_a_refusal(
    scripted: ScriptedSession,
) -> None:
    """A vehicle busy for longer than the set's tries (a starved process) answers in order:
    first the reads asked again and again before the set, all with the old value, then the
    echo. No echo in time, and older values heard on every try: the set is not refused for
    them, a read once they have come finds the value set."""
    server = _px4_params(scripted.peer)
    echo = server.handle
    await scripted.vehicle.get_param("MIS_TAKEOFF_ALT")  # known, as after the list
    loop = asyncio.get_running_loop()
    scripted.peer.on_message = lambda msg: loop.call_later(1.0, echo, msg)  # in order, late
    for _ in range(3):  # a read asked again before the set, by a server that waited for it
        scripted.vehicle.params._request_read(b"MIS_TAKEOFF_ALT")
    # their old values come during the set's tries (4 of 0.1 s here), its echoes after them
    await asyncio.sleep(0.8)

    assert await scripted.vehicle.set_param("MIS_TAKEOFF_ALT", 3.5) == 3.5
    assert server.params["MIS_TAKEOFF_ALT"] == (3.5, MAV_PARAM_TYPE_REAL32)
    assert len(scripted.peer.messages("PARAM_SET")) == 4  # every try went unanswered in time


async def test_a_vehicle_that_answers_nothing_after_the_set_is_no_answer(
    scripted: ScriptedSession,
) -> None:
    """An older value heard during the set (a read's answer), then silence: no echo and no
    answer to a read after it is no answer (504), not "the vehicle answered" its old value."""
    server = _px4_params(scripted.peer)
    echo = server.handle
    await scripted.vehicle.get_param("MIS_TAKEOFF_ALT")
    silent: list[bool] = []

    def gone_quiet(msg: mavlink.MAVLink_message) -> None:
        if msg.get_type() == "PARAM_SET" and not silent:
            silent.append(True)
            server.send_value(msg.param_id)  # the old value, still on its way
        elif not silent:
            echo(msg)

    scripted.peer.on_message = gone_quiet
    with pytest.raises(TimeoutError, match=r"no echo for parameter MIS_TAKEOFF_ALT set to 3\.5, "
                       r"nor an answer to a read after it"):
        await scripted.vehicle.set_param("MIS_TAKEOFF_ALT", 3.5)
    assert len(scripted.peer.messages("PARAM_SET")) == 4
    assert len(scripted.peer.messages("PARAM_REQUEST_READ")) == 1 + 4  # the get, the read-back


async def test_a_clamp_with_one_answer_lost_is_still_a_refusal(
    scripted: ScriptedSession,
) -> None:
    server = _px4_params(scripted.peer)
    server.clamp["MPC_XY_CRUISE"] = 20.0
    echo = server.handle
    sets: list[bool] = []

    def lossy(msg: mavlink.MAVLink_message) -> None:
        if msg.get_type() == "PARAM_SET":
            sets.append(True)
            if len(sets) == 2:
                return  # this try's answer is lost
        echo(msg)

    scripted.peer.on_message = lossy
    with pytest.raises(ParamError, match="the vehicle answered 20"):
        await scripted.vehicle.set_param("MPC_XY_CRUISE", 50.0)


def test_a_value_the_vehicle_changes_unasked_is_told_once_with_its_previous() -> None:
    """PX4 sends a parameter changed by another ground station (or its shell) unasked: the
    first value heard is no change, a new value is told with the one before, a repeat is not."""
    told: list[tuple[str, float | int, float | int]] = []
    client = ParamClient(cast(Requester, None), on_change=lambda *change: told.append(change))

    def heard(name: str, value: float | int, param_type: int) -> None:
        client.handle_param_value(mavlink.MAVLink_param_value_message(
            name.encode(), encode_param_value(value, param_type), param_type, 900, 3))

    heard("MPC_XY_VEL_MAX", 12.0, MAV_PARAM_TYPE_REAL32)
    heard("COM_RC_IN_MODE", 3, MAV_PARAM_TYPE_INT32)
    heard("MPC_XY_VEL_MAX", 12.0, MAV_PARAM_TYPE_REAL32)
    assert told == []
    heard("MPC_XY_VEL_MAX", 11.0, MAV_PARAM_TYPE_REAL32)
    heard("COM_RC_IN_MODE", 4, MAV_PARAM_TYPE_INT32)
    heard("COM_RC_IN_MODE", 4, MAV_PARAM_TYPE_INT32)
    assert told == [("MPC_XY_VEL_MAX", 12.0, 11.0), ("COM_RC_IN_MODE", 3, 4)]
    assert client.cache["MPC_XY_VEL_MAX"].value == 11.0
