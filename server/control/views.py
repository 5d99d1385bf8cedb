"""Vehicle state as the API shows it: the link's snapshot with API names (`id`, `type`,
`global`), the lease, and non-finite numbers as null (JSON has no NaN).

The snapshot is encoded by pydantic from the link's dataclasses (no copy into dicts first);
the few fields that differ between the REST body and the WebSocket message (`type`, `id`,
`lease`) are written around that one encoding, so both share it."""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from collections.abc import Callable
from typing import Any

from pydantic import ConfigDict, TypeAdapter

from server.link import StreamStats, VehicleEvent, VehicleState
from server.link.codec.snapshot import API_NAMES

# The API's names for the snapshot's fields, the wire's (generated beside the snapshot from
# the wire model); `type` is written by the callers, since the WebSocket message uses that key
# for the message's own type.
_API_NAMES = API_NAMES
# Not part of the shared encoding: the vehicle's type goes under a different key in REST and
# WS; the list of refused telemetry streams is shown on the WebSocket only, as before.
_WRITTEN_AROUND = {"mav_type", "telemetry_refused"}


@dataclasses.dataclass(frozen=True)
class _StateOut(VehicleState):
    """VehicleState with the API's field names; pydantic writes NaN/inf as null."""

    __pydantic_config__ = ConfigDict(
        alias_generator=lambda name: _API_NAMES.get(name, name), serialize_by_alias=True
    )


_STATE_JSON: TypeAdapter[VehicleState] = TypeAdapter(_StateOut)


def encode_state(state: VehicleState) -> bytes:
    """The snapshot as a JSON object without `type`, `id` and `lease`: the expensive part
    of every state the API shows, so it is done once per snapshot and shared."""
    return _STATE_JSON.dump_json(state, exclude=_WRITTEN_AROUND)


# What changes with every message from a vehicle without saying anything new about it: the
# time (the newest message's clock, the ages), the link's traffic counters and its measured
# rate. A telemetry socket that asks for states on change sends one when anything else did.
CLOCK_FIELDS: dict[str, Any] = {
    "updated_s": True, "last_heartbeat_age_s": True, "message_ages_s": True,
    "link": {"frames_in": True, "frames_out": True, "bytes_in": True, "bytes_out": True,
             "last_heartbeat_age_s": True,
             "signing": {"signed_in": True, "unsigned_in": True}},
    "link_quality": {"silent_s": True, "rate_hz": True, "heartbeat_age_s": True},
    "stream": {"since_last_ms": True},
}


def encode_steady_state(state: VehicleState) -> bytes:
    """The snapshot without the fields that change with the time alone (CLOCK_FIELDS): two
    snapshots that encode alike tell the same, however much later the second was taken."""
    exclude: dict[str, Any] = {name: True for name in _WRITTEN_AROUND} | CLOCK_FIELDS
    return _STATE_JSON.dump_json(state, exclude=exclude)


LeaseStatus = tuple[str | None, float | None]
_json_string: Callable[[str], str] = json.encoder.encode_basestring_ascii
# the REST state's key for the vehicle's type (the wire's name for the snapshot's mav_type)
_TYPE_KEY = _json_string(API_NAMES["mav_type"])


def _json_or_null(value: str | float | None) -> str:
    # what json.dumps writes, without its per-call overhead (a state message is built per tick)
    if isinstance(value, str):
        return _json_string(value)
    if value is None or not math.isfinite(value):
        return "null"
    return repr(float(value))


def _lease_json(lease: LeaseStatus) -> str:
    holder, expires_in_s = lease
    return f'{{"holder":{_json_or_null(holder)},"expires_in_s":{_json_or_null(expires_in_s)}}}'


@functools.lru_cache(maxsize=256)
def _message_head(sysid: int, mav_type: str, telemetry_refused: tuple[str, ...]) -> str:
    # the same for every snapshot of a vehicle until its type or refusals change
    return (
        f'{{"type":"state","vehicle":{sysid},"id":{sysid},"vehicle_type":{json.dumps(mav_type)},'
        f'"telemetry_refused":{json.dumps(list(telemetry_refused))},'
    )


def state_json(state: VehicleState, body: bytes, lease: LeaseStatus) -> bytes:
    """GET /vehicles/{id}: the encoded body with the vehicle's `id`, `type` and `lease`."""
    vehicle_type = _json_string(state.mav_type)
    head = f'{{"id":{state.sysid},{_TYPE_KEY}:{vehicle_type},"lease":{_lease_json(lease)},'
    return head.encode() + body[1:]


def state_message(state: VehicleState, body: bytes, lease: LeaseStatus) -> str:
    """The telemetry socket's `{type: "state"}` message: `type` names the message, so the
    vehicle's type travels as `vehicle_type`."""
    head = _message_head(state.sysid, state.mav_type, state.telemetry_refused)
    return f'{head}"lease":{_lease_json(lease)},{body[1:].decode()}'


def finite(value: Any) -> Any:
    """The value with every NaN/inf float, however deeply nested, replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: finite(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [finite(item) for item in value]
    return value


def summary_dict(state: VehicleState) -> dict[str, Any]:
    result: dict[str, Any] = finite(
        {
            "id": state.sysid,
            "sysid": state.sysid,
            "type": state.mav_type,
            "autopilot": state.autopilot,
            "connected": state.connected,
            "mode": state.mode,
            "armed": state.armed,
            "link": dataclasses.asdict(state.link),
        }
    )
    return result


def stream_dict(stats: StreamStats) -> dict[str, Any]:
    result: dict[str, Any] = finite(dataclasses.asdict(stats))
    return result


def event_message(vehicle_id: int, event: VehicleEvent) -> dict[str, Any]:
    if event.kind == "statustext":
        return {
            "type": "statustext",
            "vehicle": vehicle_id,
            "time_s": event.time_s,
            **finite(dict(event.data)),
        }
    return {
        "type": "event",
        "vehicle": vehicle_id,
        "kind": event.kind,
        "time_s": event.time_s,
        "data": finite(_jsonable(event.data)),
    }


def _jsonable(value: Any) -> Any:
    return json.loads(json.dumps(value, default=str))
