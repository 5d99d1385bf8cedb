"""PX4's parameter protocol (mavlink_parameters): list, read by name or index, set.

A set is answered with the new PARAM_VALUE on every link, as PX4 does; a parameter the
vehicle does not have gets no answer at all.
"""

from __future__ import annotations

from collections.abc import Callable

from pymavlink.dialects.v20 import development as mavlink

from sim.lib.params import ParamStore
from sim.mavlink.vehicle_interface import Link, Message


class MavlinkParameters:
    def __init__(self, params: ParamStore, broadcast: Callable[[Message], None]) -> None:
        self._params = params
        self._broadcast = broadcast

    def _param_value(self, name: str) -> Message:
        params = self._params
        return mavlink.MAVLink_param_value_message(
            name.encode(), params.wire_value(name), params.param_type(name), len(params),
            params.index(name))

    def handle_request_list(self, link: Link, msg: Message) -> None:
        for name in self._params:
            link.send(self._param_value(name))

    def handle_request_read(self, link: Link, msg: Message) -> None:
        params = self._params
        name: str | None = msg.param_id if msg.param_index < 0 else params.name_at(msg.param_index)
        if name is None or name not in params:
            return  # PX4 stays silent about parameters it does not have
        link.send(self._param_value(name))

    def handle_set(self, link: Link, msg: Message) -> None:
        name = msg.param_id
        if name not in self._params:
            return
        self._params.set_from_wire(name, msg.param_value)
        self._broadcast(self._param_value(name))
