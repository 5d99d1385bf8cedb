"""Every call under ``/api/v1/vehicles/{vehicle_id}``, written once: its name, method,
path, who may make it, its request, query and path models and its answer.

What follows from it: the fleet edge's table (``server/http/vehicle_calls.py`` pairs each
call with the function its REST route runs), the command routes (``server/api/routes/
commands.py``), the Python client's paths and the page's call table (``web/calls.js``,
written by ``python -m tools.gen_calls_js``; ``tests/test_calls_js.py`` fails when it is
stale). ``tests/fleet/test_edge_parity.py`` holds every REST route under a vehicle to it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any, Literal

from pydantic import BaseModel, Field

from skyhelm_wire import commands, control, intents, params, sticks
from skyhelm_wire.setpoints import SentSetpointOut, SetpointBody
from skyhelm_wire.state import StreamOut, VehicleStateOut

Method = Literal["GET", "POST", "PUT", "DELETE"]
# who may make a call: any token (the vehicle known; connected for "connected"), the pilot
# token ("pilot": the lease's own calls), the pilot holding the vehicle's lease ("control")
Access = Literal["read", "connected", "pilot", "control"]

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


@dataclass(frozen=True)
class CallSpec:
    """One call: ``path`` is under the vehicle ("" for the vehicle itself, ``{name}`` for a
    path parameter); ``body`` None takes no body, ``body_required`` False a body that may
    be left out (every field has a default); ``answer`` None answers 204 with no body."""

    name: str
    method: Method
    path: str
    access: Access
    answer: Any
    body: Any = None
    body_required: bool = False
    query: type[BaseModel] | None = None
    path_params: type[BaseModel] | None = None


def _command(name: str, path: str, body: type[BaseModel] | None) -> CallSpec:
    """A command: no body for an empty model, an optional one when every field has a
    default."""
    if body is not None and not body.model_fields:
        body = None
    required = body is not None and any(f.is_required() for f in body.model_fields.values())
    return CallSpec(name, "POST", path, "control", commands.CommandResultOut, body, required)


CALLS: tuple[CallSpec, ...] = (
    CallSpec("state", "GET", "", "read", VehicleStateOut),
    CallSpec("stream", "GET", "stream", "read", StreamOut),
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
)
CALL: dict[str, CallSpec] = {call.name: call for call in CALLS}
# the commands and intents the control socket takes by name, as REST calls
COMMAND_CALLS = tuple(
    call for call in CALLS if call.answer in (commands.CommandResultOut, intents.IntentOut)
)
