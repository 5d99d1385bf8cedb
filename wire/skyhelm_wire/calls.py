"""Every REST call under ``/api/v1``, written once: its name, method, path, who may make
it, its request, query and path models and its answer. A call is the vehicle's (its path
under ``/vehicles/{vehicle_id}``) or the server's (its path under ``/api/v1``).

What follows from it: every REST route (each route module registers its handlers at the
table's method and path with ``server.http.routing.route``), the fleet edge's table
(``server/http/vehicle_calls.py`` pairs each vehicle call with the function its REST route
runs), the control socket's commands, the Python client's methods and the page's call table
(``web/calls.js``, written by ``python -m tools.gen_calls_js``; ``tests/test_calls.py``
fails when it is stale or when a route is not the table's).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any, Literal

from pydantic import BaseModel, Field

from skyhelm_wire import commands, control, intents, params, sticks
from skyhelm_wire.common import HealthOut
from skyhelm_wire.fleet import FleetOut, FleetVehicleOut, FleetVehiclePath
from skyhelm_wire.page import PageConfigOut, SessionOut
from skyhelm_wire.setpoints import SentSetpointOut, SetpointBody
from skyhelm_wire.signing import SigningBody, SigningStatusOut
from skyhelm_wire.state import StreamOut, VehicleStateOut, VehicleSummaryOut

API_PREFIX = "/api/v1"
VEHICLE_PATH = "/vehicles/{vehicle_id}"
# a fleet server runs every call of a vehicle of an edge under this path (+ the call's path)
FLEET_VEHICLE_PATH = "/fleet/edges/{edge}" + VEHICLE_PATH
Method = Literal["GET", "POST", "PUT", "DELETE"]
# who may make a call: no token ("open"), any token (the vehicle known; connected for
# "connected"), the pilot token ("pilot": the lease's own calls and the server's settings),
# the pilot holding the vehicle's lease ("control")
Access = Literal["open", "read", "connected", "pilot", "control"]
# whose call it is: the vehicle's (its path under VEHICLE_PATH) or the server's (under the API)
Scope = Literal["vehicle", "server"]
AUDIT_LIMIT_MAX = 1000

# PX4 parameter ids: at most 16 characters, ASCII letters, digits and "_"
PARAM_NAME_LENGTH = 16
PARAM_NAME_PATTERN = r"^[A-Za-z0-9_]{1,16}$"
PARAM_NAMES_PATTERN = r"^[A-Za-z0-9_]{1,16}(,[A-Za-z0-9_]{1,16})*$"
ParamName = Annotated[
    str,
    Field(pattern=PARAM_NAME_PATTERN, min_length=1, max_length=PARAM_NAME_LENGTH,
          examples=["MIS_TAKEOFF_ALT"]),
]  # fmt: skip
ParamNames = Annotated[
    str,
    Field(pattern=PARAM_NAMES_PATTERN,
          description="comma-separated, each as a parameter's name; omit for all",
          examples=["MIS_TAKEOFF_ALT,MPC_XY_VEL_MAX"]),
]  # fmt: skip


class SetpointQuery(BaseModel):
    live: bool = Field(False, description="hold-to-fly input, watched by the deadman")


class ParamsQuery(BaseModel):
    names: ParamNames | None = None


class ParamPath(BaseModel):
    name: ParamName


class TakeoverPath(BaseModel):
    request_id: str


class AuditQuery(BaseModel):
    vehicle: int | None = Field(None, ge=0, le=255, description="one vehicle's only")
    limit: int = Field(100, ge=1, le=AUDIT_LIMIT_MAX)


class TilePath(BaseModel):
    z: int = Field(ge=0, description="zoom level")
    x: int = Field(ge=0, description="column, from the west")
    y: int = Field(ge=0, description="row, from the north (XYZ, as Leaflet)")
    ext: str = Field(pattern=r"^[A-Za-z0-9]+$",
                     description="the archive's tile format: png, jpg or webp")


@dataclass(frozen=True)
class CallSpec:
    """One call: ``path`` is under the vehicle ("" for the vehicle itself, ``{name}`` for a
    path parameter) or, for a ``scope`` "server" call, under the API; ``body`` None takes
    no body, ``body_required`` False a body that may be left out (every field has a
    default); ``answer`` None answers 204 with no body, ``bytes`` a body that is not JSON."""

    name: str
    method: Method
    path: str
    access: Access
    answer: Any
    body: Any = None
    body_required: bool = False
    query: type[BaseModel] | None = None
    path_params: type[BaseModel] | None = None
    scope: Scope = "vehicle"

    @property
    def route(self) -> str:
        """The path under the API (``/vehicles/{vehicle_id}/arm``, ``/health``)."""
        if self.scope == "server":
            return f"/{self.path}"
        return f"{VEHICLE_PATH}/{self.path}" if self.path else VEHICLE_PATH


def _command(name: str, path: str, body: type[BaseModel] | None) -> CallSpec:
    """A command: no body for an empty model, an optional one when every field has a
    default."""
    if body is not None and not body.model_fields:
        body = None
    required = body is not None and any(f.is_required() for f in body.model_fields.values())
    return CallSpec(name, "POST", path, "control", commands.CommandResultOut, body, required)


def _server(
    name: str, method: Method, path: str, access: Access, answer: Any, body: Any = None,
    *, query: type[BaseModel] | None = None, path_params: type[BaseModel] | None = None,
) -> CallSpec:
    """A call of the server's, not of one vehicle."""
    return CallSpec(name, method, path, access, answer, body, body is not None, query,
                    path_params, "server")  # fmt: skip


CALLS: tuple[CallSpec, ...] = (
    _server("health", "GET", "health", "open", HealthOut),
    _server("open_session", "POST", "session", "read", SessionOut),
    _server("close_session", "DELETE", "session", "read", None),
    _server("page_config", "GET", "config", "read", PageConfigOut),
    _server("tile", "GET", "tiles/{z}/{x}/{y}.{ext}", "read", bytes, path_params=TilePath),
    _server("vehicles", "GET", "vehicles", "read", list[VehicleSummaryOut]),
    CallSpec("state", "GET", "", "read", VehicleStateOut),
    CallSpec("stream", "GET", "stream", "read", StreamOut),
    _server("audit", "GET", "control/audit", "read", list[control.AuditEntryOut],
            query=AuditQuery),
    CallSpec("control_status", "GET", "control", "read", control.ControlStatusOut),
    CallSpec("acquire", "POST", "control", "pilot", control.LeaseOut, control.ControlBody),
    CallSpec("renew", "PUT", "control", "pilot", control.LeaseOut, control.RenewBody),
    CallSpec("release", "DELETE", "control", "pilot", None),
    CallSpec("answer_takeover", "POST", "control/requests/{request_id}", "pilot",
             control.TakeoverAnswerOut, control.TakeoverAnswerBody, True,
             path_params=TakeoverPath),
    CallSpec("set_setpoint", "PUT", "setpoint", "control", SentSetpointOut, SetpointBody, True,
             query=SetpointQuery),
    CallSpec("sticks", "GET", "sticks", "read", sticks.SticksOut),
    CallSpec("fly_sticks", "PUT", "sticks", "control", sticks.SticksOut, sticks.SticksBody, True),
    CallSpec("stop_sticks", "DELETE", "sticks", "control", sticks.SticksOut),
    CallSpec("params", "GET", "params", "connected", params.ParamsOut, query=ParamsQuery),
    CallSpec("param_metadata", "GET", "params/metadata", "connected", params.ParamMetadataOut),
    CallSpec("param", "GET", "params/{name}", "connected", params.ParamOut,
             path_params=ParamPath),
    CallSpec("set_param", "PUT", "params/{name}", "control", params.ParamOut,
             params.ParamValueBody, True, path_params=ParamPath),
    _command("arm", "arm", commands.ArmBody),
    _command("disarm", "disarm", commands.ArmBody),
    _command("takeoff", "takeoff", commands.TakeoffBody),
    _command("land", "land", None),
    _command("rtl", "rtl", None),
    _command("hold", "hold", None),
    _command("mode", "mode", commands.ModeBody),
    _command("reposition", "reposition", commands.RepositionBody),
    _command("vtol_transition", "vtol/transition", commands.VtolTransitionBody),
    _command("origin", "origin", commands.OriginBody),
    _command("home", "home", commands.HomeBody),
    _command("offboard_start", "offboard/start", commands.OffboardStartBody),
    _command("offboard_stop", "offboard/stop", commands.OffboardStopBody),
    CallSpec("brake", "POST", "intents/brake", "control", intents.IntentOut),
    CallSpec("velocity", "PUT", "intents/velocity", "control", intents.IntentOut,
             intents.VelocityIntentBody, True),
    CallSpec("offset", "POST", "intents/offset", "control", intents.IntentOut,
             intents.OffsetIntentBody, True),
    CallSpec("goto", "POST", "intents/goto", "control", intents.IntentOut,
             intents.GotoIntentBody, True),
    _server("signing_status", "GET", "signing", "read", SigningStatusOut),
    _server("set_signing", "POST", "signing", "pilot", SigningStatusOut, SigningBody),
    # a fleet server's (--fleet) own reads
    _server("fleet", "GET", "fleet", "read", FleetOut),
    _server("fleet_vehicles", "GET", "fleet/vehicles", "read", list[FleetVehicleOut]),
    _server("fleet_vehicle", "GET", FLEET_VEHICLE_PATH.removeprefix("/"), "read", dict[str, Any],
            path_params=FleetVehiclePath),
)
CALL: dict[str, CallSpec] = {call.name: call for call in CALLS}
# the calls of one vehicle, each under /vehicles/{vehicle_id} (what the fleet edge serves)
VEHICLE_CALLS = tuple(call for call in CALLS if call.scope == "vehicle")
# the commands and intents the control socket takes by name, as REST calls
COMMAND_CALLS = tuple(
    call for call in CALLS if call.answer in (commands.CommandResultOut, intents.IntentOut)
)
