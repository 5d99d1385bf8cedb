"""A vehicle's reads, setpoint, sticks and parameters as REST and the fleet edge run them:
plain arguments in, the answer's model out, refusals raised as the link's and the control
core's exceptions (the commands and intents are ``operations.py``)."""

from __future__ import annotations

from dataclasses import asdict

from server.control.deadman import Deadman
from server.control.operations import sent_out
from server.control.publishers import StatePublishers
from server.control.refusals import InvalidInput
from server.control.views import finite, stream_dict
from server.link import MetadataError, ParamInfo, Sticks, Vehicle
from server.link.plugins.manual_control import MANUAL_CONTROL_RATE_HZ
from skyhelm_wire.params import (
    ParamChoiceOut,
    ParamInfoOut,
    ParamMetadataOut,
    ParamOut,
    ParamsOut,
    ParamValueBody,
)
from skyhelm_wire.setpoints import SentSetpointOut, SetpointBody
from skyhelm_wire.state import StreamOut
from skyhelm_wire.sticks import SticksBody, SticksOut


def state_json(publishers: StatePublishers, vehicle: Vehicle) -> bytes:
    """The state publisher's latest encoding (the one the telemetry sockets send), with the
    lease as it is now."""
    return publishers.for_vehicle(vehicle).rest_json()


def stream_out(vehicle: Vehicle) -> StreamOut:
    """Setpoint streamer figures, measured since the stream last started."""
    return StreamOut.model_validate(stream_dict(vehicle.stream_stats()))


async def put_setpoint(
    deadman: Deadman, vehicle: Vehicle, body: SetpointBody, *, live: bool
) -> SentSetpointOut:
    """Replace the streamed setpoint (the link refuses what breaks the envelope or what PX4
    would drop) and tell the deadman whether it is live input."""
    sent = await vehicle.set_setpoint(body.to_link())
    deadman.watch_live(vehicle.sysid, live=live)
    return sent_out(sent)


def sticks_out(vehicle: Vehicle) -> SticksOut:
    sticks = vehicle.sticks
    return SticksOut(
        active=vehicle.sticks_active,
        sticks=SticksBody(**asdict(sticks)) if sticks is not None else None,
        rate_hz=MANUAL_CONTROL_RATE_HZ,
        stream=StreamOut(**asdict(vehicle.sticks_stats())),
    )


def fly_sticks(deadman: Deadman, vehicle: Vehicle, body: SticksBody) -> SticksOut:
    """Send these sticks from the next tick on and feed the deadman."""
    vehicle.set_sticks(Sticks(**body.model_dump()))
    deadman.feed_sticks(vehicle.sysid)
    return sticks_out(vehicle)


def stop_sticks(deadman: Deadman, vehicle: Vehicle) -> SticksOut:
    vehicle.stop_sticks("stopped by the pilot")
    deadman.stop_sticks_watch(vehicle.sysid)
    return sticks_out(vehicle)


def param_names(names: str | None) -> list[str] | None:
    """The ids of ``names`` (checked against the wire's PARAM_NAMES_PATTERN), or None: all."""
    return None if names is None else names.split(",")


async def get_params(vehicle: Vehicle, names: str | None) -> ParamsOut:
    return ParamsOut(params=finite(await vehicle.get_params(param_names(names))))


async def get_param(vehicle: Vehicle, name: str) -> ParamOut:
    return ParamOut(name=name, value=finite(await vehicle.get_param(name)))


async def set_param(vehicle: Vehicle, name: str, body: ParamValueBody) -> ParamOut:
    """Set it, held to the range of the vehicle's metadata unless the body says ``force``
    (a parameter the metadata does not describe, or a vehicle serving none, is not held)."""
    if not body.force:
        check_param_range(await _param_info(vehicle, name), body.value)
    return ParamOut(name=name, value=finite(await vehicle.set_param(name, body.value)))


def check_param_range(info: ParamInfo | None, value: float | int) -> None:
    """422 naming the field, the range and the metadata's words when value is outside it."""
    why = None if info is None else info.out_of_range(value)
    if info is None or why is None:
        return
    raise InvalidInput(
        f"{why}; send force: true to set it anyway", field="value",
        minimum=info.min, maximum=info.max, units=info.units or None,
        description=info.short_desc or None,
    )  # fmt: skip


async def _param_info(vehicle: Vehicle, name: str) -> ParamInfo | None:
    try:
        return (await vehicle.get_param_metadata()).get(name)
    except MetadataError:
        return None


async def get_param_metadata(vehicle: Vehicle) -> ParamMetadataOut:
    try:
        described = await vehicle.get_param_metadata()
    except MetadataError as e:
        return ParamMetadataOut(available=False, error=str(e), parameters={})
    return ParamMetadataOut(
        available=True, parameters={name: _info_out(info) for name, info in described.items()}
    )


def _info_out(info: ParamInfo) -> ParamInfoOut:
    fields = asdict(info)
    fields["values"] = [ParamChoiceOut(**asdict(c)) for c in info.values]
    fields["bitmask"] = [ParamChoiceOut(**asdict(c)) for c in info.bitmask]
    return ParamInfoOut(**fields)
