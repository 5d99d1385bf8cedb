"""The calls the client writes by hand (their arguments and answers shaped for scripts),
defined once for the blocking and the asyncio client.

An operation builds a :class:`Call` (the method and path of the wire's table, the body)
and hands it to one of the client's senders, chosen by what the answer becomes (a command
result, the lease, the state, a parameter value, nothing). :class:`SkyHelm` sends and
returns the value; :class:`AsyncSkyHelm` returns an awaitable of it: the type parameters of
:class:`Calls` say which, so both clients are typed from this one list. Every other call of
the table is a method written by ``python -m tools.gen_client`` (``generated.py``),
answering the table's model.
"""

from __future__ import annotations

import math
import os
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Generic, Literal, TypeVar
from urllib.parse import quote

import httpx

from skyhelm_client import exit_release
from skyhelm_client.errors import NoLease, error_for, timed_out
from skyhelm_client.models import Lease, State
from skyhelm_client.urls import API_PREFIX, split_url
from skyhelm_wire.calls import CALL
from skyhelm_wire.setpoint_kinds import SetpointKind, describe

_Cmd = TypeVar("_Cmd")
_Lease = TypeVar("_Lease")
_State = TypeVar("_State")
_Value = TypeVar("_Value")
_None = TypeVar("_None")
_Intent = TypeVar("_Intent")
_Sent = TypeVar("_Sent")
_Params = TypeVar("_Params")
_Audit = TypeVar("_Audit")

# Long enough for a takeover the holder is asked about (takeover_ask_s, 10 s by default)
# and for a mode switch the vehicle confirms.
DEFAULT_TIMEOUT_S = 30.0

LeaseEffect = Literal["keep", "grant", "drop"]


@dataclass(frozen=True)
class Call:
    """One HTTP request. ``control`` calls carry the lease id; ``lease`` says what the
    answer does to the lease the client holds; ``pick`` takes one key of the answer, once
    the whole answer is validated with ``model`` (the table's answer model)."""

    method: str
    path: str
    body: Any = None
    params: dict[str, str] = field(default_factory=dict)
    control: bool = False
    lease: LeaseEffect = "keep"
    pick: str | None = None
    model: Any = None


def setpoint_json(setpoint: SetpointKind | Mapping[str, Any]) -> dict[str, Any]:
    """A setpoint kind (``PositionNed(...)``) or its JSON form, as the API takes it."""
    body = describe(setpoint) if isinstance(setpoint, SetpointKind) else dict(setpoint)
    return {key: value for key, value in body.items() if value is not None}


def given(**values: Any) -> dict[str, Any]:
    """The arguments that were given (not None), as the JSON body named after them."""
    return {key: value for key, value in values.items() if value is not None}


def query(**values: Any) -> dict[str, str]:
    """The query parameters that were given, as the server reads them (``true``)."""
    return {key: json_text(value) for key, value in values.items() if value is not None}


def json_body(response: httpx.Response) -> Any:
    """The answer's JSON; its bytes when it is not JSON (a map tile); None when empty."""
    if not response.content:
        return None
    if response.headers.get("content-type", "").startswith("application/json"):
        return response.json()
    return response.content


def json_text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def _arguments(values: dict[str, Any]) -> dict[str, Any]:
    """A method's arguments (its ``locals()`` on entry) that were given, as the JSON body
    whose fields they are named after."""
    return given(**{key: value for key, value in values.items() if key != "self"})


@dataclass
class Waiting:
    """A ``wait_until`` in progress: ``met(state)`` until the predicate holds, raising
    ``WaitTimedOut`` past the deadline."""

    predicate: Callable[[State], bool]
    deadline: float
    what: str
    clock: Callable[[], float]

    def met(self, state: State) -> bool:
        if self.predicate(state):
            return True
        if self.clock() >= self.deadline:
            raise timed_out(self.what, state)
        return False


class Calls(ABC, Generic[_Cmd, _Lease, _State, _Value, _None, _Intent, _Sent, _Params, _Audit]):
    """The API of one vehicle (and the server's shared reads), for a client that sends each
    kind of answer through its own sender."""

    # the calls of the wire's table written here by hand; tools.gen_client writes the others
    BY_HAND: ClassVar[frozenset[str]] = frozenset({
        "state", "acquire", "renew", "release", "set_setpoint", "params", "param", "set_param",
        "arm", "disarm", "takeoff", "land", "rtl", "hold", "mode", "reposition",
        "vtol_transition", "origin", "home", "offboard_start", "offboard_stop", "brake",
        "velocity", "offset", "goto", "audit",
    })  # fmt: skip
    # a call's method when it is not the call's name
    METHOD_NAMES: ClassVar[dict[str, str]] = {
        "mode": "set_mode", "origin": "set_origin", "home": "set_home", "stream": "stream_stats",
    }  # fmt: skip

    def __init__(
        self,
        url: str,
        token: str | None = None,
        *,
        vehicle: int = 1,
        timeout_s: float = DEFAULT_TIMEOUT_S,
    ) -> None:
        self.base_url, self.token = split_url(url, token)
        self._open(timeout_s)
        self.vehicle_id = vehicle
        self.lease: Lease | None = None
        # when the lease was last renewed (any control call renews it), on the client's clock
        self._renewed_at = -math.inf

    # -- the senders each client provides ----------------------------------------------

    # what each kind of answer becomes: the value (blocking) or an awaitable of it (asyncio)
    _command: Callable[[Call], _Cmd]
    _lease: Callable[[Call], _Lease]
    _state: Callable[[Call], _State]
    _value: Callable[[Call], _Value]  # a parameter's value: float, None when not finite
    _none: Callable[[Call], _None]
    _intent: Callable[[Call], _Intent]  # an Answer[IntentOut]
    _sent: Callable[[Call], _Sent]  # an Answer[SentSetpointOut]
    _params: Callable[[Call], _Params]  # {name: value}
    _audit: Callable[[Call], _Audit]  # a list[Answer[AuditEntryOut]]
    # reads the state (renewing a held lease) until the wait is over, pausing between reads
    _wait: Callable[[Waiting, float], _State]

    @abstractmethod
    def _open(self, timeout_s: float) -> None:
        """Open the HTTP connection pool, each request bounded by ``timeout_s``."""

    @abstractmethod
    def _now(self) -> float: ...

    # -- what both clients share around a request ----------------------------------------

    def _request(self, call: Call) -> dict[str, Any]:
        headers = {"Authorization": f"Bearer {self.token}"}
        if call.control and self.lease is not None:
            headers["X-Lease-Id"] = self.lease.lease_id
        request: dict[str, Any] = {
            "method": call.method,
            "url": f"{self.base_url}{API_PREFIX}{call.path}",
            "headers": headers,
            "params": call.params,
        }
        if call.body is not None:
            request["json"] = call.body
        return request

    def _answer(self, call: Call, status: int, body: Any) -> Any:
        """The answer's JSON (or the picked key), after the lease bookkeeping; raises the
        typed error for a refusal."""
        if status >= 300:
            error = error_for(status, body)
            if isinstance(error, NoLease) and call.control:
                self._lease_gone()
            raise error
        if call.lease == "grant":
            self.lease = Lease.from_json(body)
            exit_release.holding(self, lambda: self._request(self._release_call()))
        elif call.lease == "drop":
            self._lease_gone()
        if call.control and self.lease is not None:
            self._renewed_at = self._now()
        if call.pick is None:
            return body
        if call.model is not None:
            call.model.model_validate(body)
        return body[call.pick]

    def _lease_gone(self) -> None:
        self.lease = None
        exit_release.released(self)

    def _renew_due(self) -> bool:
        """A wait renews a held lease at a third of its TTL, so waiting never loses it."""
        return self.lease is not None and self._now() - self._renewed_at > self.lease.ttl_s / 3

    def _named(
        self,
        name: str,
        body: Any = None,
        *,
        params: dict[str, str] | None = None,
        path: Mapping[str, str] | None = None,
        lease: LeaseEffect = "keep",
        pick: str | None = None,
    ) -> Call:
        """The call ``name`` of the wire's table (its method and path; a vehicle's on this
        vehicle); the pilot's and the control calls carry the lease id."""
        spec = CALL[name]
        values = {key: quote(value, safe="") for key, value in (path or {}).items()}
        where = spec.route.format(**{"vehicle_id": str(self.vehicle_id), **values})
        return Call(
            spec.method, where, body, params or {},
            control=spec.access in ("pilot", "control"), lease=lease, pick=pick,
            model=spec.answer if pick is not None else None,
        )  # fmt: skip

    # -- reads ------------------------------------------------------------------------

    def state(self) -> _State:
        return self._state(self._named("state"))

    def wait_until(
        self,
        predicate: Callable[[State], bool],
        timeout_s: float,
        *,
        what: str = "the condition",
        poll_s: float = 0.1,
    ) -> _State:
        """Read the state every ``poll_s`` until ``predicate(state)`` holds, and answer that
        state; a held lease is renewed meanwhile. Raises ``WaitTimedOut`` (a TimeoutError)
        after ``timeout_s``."""
        waiting = Waiting(predicate, self._now() + timeout_s, f"{what} ({timeout_s} s)", self._now)
        return self._wait(waiting, poll_s)

    def audit(
        self, *, limit: int = 100, vehicle: int | None = None, all_vehicles: bool = False
    ) -> _Audit:
        """The newest ``limit`` control and deadman events of the audit log, oldest first:
        this client's vehicle's (``vehicle``: another one's; ``all_vehicles=True``: every
        vehicle's, as ``GET /control/audit`` without ``vehicle``)."""
        if all_vehicles and vehicle is not None:
            raise ValueError("audit: give vehicle or all_vehicles=True, not both")
        if not all_vehicles and vehicle is None:
            vehicle = self.vehicle_id
        return self._audit(self._named("audit", params=query(vehicle=vehicle, limit=limit)))

    # -- control ----------------------------------------------------------------------

    def _control(self, method: str, body: dict[str, Any] | None) -> _Lease:
        return self._lease(self._named("acquire" if method == "POST" else "renew", body,
                                       lease="grant"))  # fmt: skip

    def acquire(self, *, ttl_s: float | None = None, client_name: str | None = None) -> _Lease:
        """Take the control lease (409 :class:`Refused` naming the holder while someone else
        has it); ``ttl_s`` within the server's bounds, its default otherwise. The lease is
        given back when the script ends (``exit_release``); this process's id goes along,
        so a server on the same machine ends it too if the process is killed."""
        return self._control("POST", {**_arguments(locals()), "client_pid": os.getpid()})

    def take_over(
        self, *, force: bool = False, ttl_s: float | None = None, client_name: str | None = None
    ) -> _Lease:
        """Ask the holder for control (granted: the lease; denied or unanswered: 409), or
        with ``force`` take it at once."""
        body = {"takeover": True, **_arguments(locals()), "client_pid": os.getpid()}
        return self._control("POST", body)

    def renew(self, *, ttl_s: float | None = None, client_name: str | None = None) -> _Lease:
        """Renew the lease (any control call also does), optionally with a new TTL or
        label."""
        return self._control("PUT", _arguments(locals()) or None)

    def _release_call(self) -> Call:
        return self._named("release", lease="drop")

    def release(self) -> _None:
        return self._none(self._release_call())

    # -- commands ---------------------------------------------------------------------

    def arm(self, *, force: bool = False) -> _Cmd:
        return self._command(self._named("arm", {"force": force}))

    def disarm(self, *, force: bool = False) -> _Cmd:
        return self._command(self._named("disarm", {"force": force}))

    def takeoff(self, *, altitude_m: float | None = None) -> _Cmd:
        """Climb to ``altitude_m`` above home (default: the vehicle's MIS_TAKEOFF_ALT)."""
        return self._command(self._named("takeoff", given(altitude_m=altitude_m)))

    def land(self) -> _Cmd:
        return self._command(self._named("land"))

    def rtl(self) -> _Cmd:
        return self._command(self._named("rtl"))

    def hold(self) -> _Cmd:
        return self._command(self._named("hold"))

    def set_mode(self, mode: str) -> _Cmd:
        """A PX4 mode by name (``"OFFBOARD"``, ``"POSCTL"``, ...), confirmed by the vehicle."""
        return self._command(self._named("mode", {"mode": mode}))

    def reposition(
        self, lat_deg: float, lon_deg: float, alt_rel_m: float | None = None, *,
        alt_amsl_m: float | None = None, ground_speed_m_s: float | None = None,
        yaw_deg: float | None = None, loiter_radius_m: float | None = None,
    ) -> _Cmd:  # fmt: skip
        """Fly to a point and hold there (ends OFFBOARD); the altitude above home or AMSL
        (neither: the current one); the rest None: PX4's own (MPC_XY_CRUISE, the heading
        now, NAV_LOITER_RAD)."""
        return self._command(self._named("reposition", _arguments(locals())))

    def vtol_transition(
        self,
        to: Literal["fixed_wing", "multicopter"],
        *,
        immediate: bool = False,
        wait: bool = True,
    ) -> _Cmd:
        body = {"to": to, "immediate": immediate, "wait": wait}
        return self._command(self._named("vtol_transition", body))

    def set_origin(self, *, lat_deg: float, lon_deg: float, alt_amsl_m: float) -> _Cmd:
        body = {"lat_deg": lat_deg, "lon_deg": lon_deg, "alt_amsl_m": alt_amsl_m}
        return self._command(self._named("origin", body))

    def set_home(
        self,
        *,
        lat_deg: float | None = None,
        lon_deg: float | None = None,
        alt_amsl_m: float | None = None,
    ) -> _Cmd:
        """Home at the point given, or where the vehicle is without one."""
        return self._command(self._named("home", _arguments(locals())))

    def offboard_start(self, setpoint: SetpointKind | Mapping[str, Any] | None = None) -> _Cmd:
        """Stream ``setpoint`` (default: hold here) and switch to OFFBOARD."""
        body = {"setpoint": setpoint_json(setpoint)} if setpoint is not None else {}
        return self._command(self._named("offboard_start", body))

    def offboard_stop(self, *, then_mode: str = "HOLD") -> _Cmd:
        return self._command(self._named("offboard_stop", {"then_mode": then_mode}))

    # -- setpoints and intents --------------------------------------------------------

    def set_setpoint(
        self, setpoint: SetpointKind | Mapping[str, Any], *, live: bool = False
    ) -> _Sent:
        """Replace the streamed setpoint; ``live`` ones (hold-to-fly input) are braked by the
        deadman when no update follows in time. Answers what is sent:
        ``{setpoint, message, frame, type_mask}``."""
        live_query = {"live": "true"} if live else None
        return self._sent(self._named("set_setpoint", setpoint_json(setpoint), params=live_query))

    def brake(self) -> _Intent:
        """Brake, then hold where the vehicle stops (HOLD mode when not streaming). Answers
        ``{intent, via, setpoint, command, target, live}``, as every intent does."""
        return self._intent(self._named("brake"))

    def velocity(
        self,
        *,
        frame: Literal["body", "ned"] = "body",
        forward_m_s: float | None = None,
        right_m_s: float | None = None,
        north_m_s: float | None = None,
        east_m_s: float | None = None,
        up_m_s: float | None = None,
        yaw_rate_deg_s: float | None = None,
        hold_altitude: bool = False,
        live: bool = True,
    ) -> _Intent:
        """Fly at a velocity: forward/right in the body frame or north/east, ``up_m_s``
        positive up, ``yaw_rate_deg_s`` clockwise seen from above (``hold_altitude``: keep
        the altitude instead). Live input by default: without a new call within the
        server's deadman timeout the vehicle brakes and holds; ``live=False`` flies it until
        replaced. Needs OFFBOARD (``offboard_start``) to fly."""
        return self._intent(self._named("velocity", _arguments(locals())))

    def offset(
        self,
        *,
        north_m: float = 0.0,
        east_m: float = 0.0,
        up_m: float = 0.0,
        yaw_deg: float | None = None,
    ) -> _Intent:
        """Go by an offset from where the vehicle is (checked against the envelope)."""
        return self._intent(self._named("offset", _arguments(locals())))

    def goto(
        self, lat_deg: float, lon_deg: float, alt_rel_m: float | None = None, *,
        yaw_deg: float | None = None,
    ) -> _Intent:  # fmt: skip
        """Go to a point, ``alt_rel_m`` above home (default: the current altitude)."""
        return self._intent(self._named("goto", _arguments(locals())))

    # -- parameters -------------------------------------------------------------------

    def params(self, *names: str) -> _Params:
        """``{name: value}`` for the names given, or every parameter."""
        params = {"names": ",".join(names)} if names else {}
        return self._params(self._named("params", params=params, pick="params"))

    def param(self, name: str) -> _Value:
        """A parameter's value (None: not a finite number)."""
        return self._value(self._named("param", path={"name": name}, pick="value"))

    def set_param(self, name: str, value: float, *, force: bool = False) -> _Value:
        """Set a parameter; answers the value the vehicle echoed. A value outside the range
        of the vehicle's metadata is refused (422) unless ``force``."""
        body = {"value": value, "force": True} if force else {"value": value}
        call = self._named("set_param", body, path={"name": name}, pick="value")
        return self._value(call)
