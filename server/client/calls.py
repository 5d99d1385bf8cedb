"""Every call the client makes, defined once for the blocking and the asyncio client.

An operation builds a :class:`Call` (method, path, body) and hands it to one of the
client's senders, chosen by what the answer becomes (a command result, the lease, the
state, JSON, a parameter value, nothing). :class:`SkyHelm` sends and returns the value;
:class:`AsyncSkyHelm` returns an awaitable of it: the type parameters of :class:`Calls`
say which, so both clients are typed from this one list.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Generic, Literal, TypeVar

from server.client.errors import NoLease, error_for
from server.client.models import Lease
from server.client.urls import API_PREFIX, split_url
from server.link.setpoint_kinds import SetpointKind, describe

_Cmd = TypeVar("_Cmd")
_Lease = TypeVar("_Lease")
_State = TypeVar("_State")
_Json = TypeVar("_Json")
_Value = TypeVar("_Value")
_None = TypeVar("_None")

# Long enough for a takeover the holder is asked about (takeover_ask_s, 10 s by default)
# and for a mode switch the vehicle confirms.
DEFAULT_TIMEOUT_S = 30.0

LeaseEffect = Literal["keep", "grant", "drop"]


@dataclass(frozen=True)
class Call:
    """One HTTP request. ``control`` calls carry the lease id; ``lease`` says what the
    answer does to the lease the client holds; ``pick`` takes one key of the answer."""

    method: str
    path: str
    body: Any = None
    params: dict[str, str] = field(default_factory=dict)
    control: bool = False
    lease: LeaseEffect = "keep"
    pick: str | None = None


def setpoint_json(setpoint: SetpointKind | Mapping[str, Any]) -> dict[str, Any]:
    """A setpoint kind (``PositionNed(...)``) or its JSON form, as the API takes it."""
    body = describe(setpoint) if isinstance(setpoint, SetpointKind) else dict(setpoint)
    return {key: value for key, value in body.items() if value is not None}


def _given(**values: Any) -> dict[str, Any]:
    return {key: value for key, value in values.items() if value is not None}


class Calls(ABC, Generic[_Cmd, _Lease, _State, _Json, _Value, _None]):
    """The API of one vehicle (and the server's shared reads), for a client that sends each
    kind of answer through its own sender."""

    def __init__(self, url: str, token: str | None = None, *, vehicle: int = 1) -> None:
        self.base_url, self.token = split_url(url, token)
        self.vehicle_id = vehicle
        self.lease: Lease | None = None
        # when the lease was last renewed (any control call renews it), on the client's clock
        self._renewed_at = -math.inf

    # -- the senders each client provides ----------------------------------------------

    @abstractmethod
    def _command(self, call: Call) -> _Cmd: ...

    @abstractmethod
    def _lease(self, call: Call) -> _Lease: ...

    @abstractmethod
    def _state(self, call: Call) -> _State: ...

    @abstractmethod
    def _json(self, call: Call) -> _Json: ...

    @abstractmethod
    def _value(self, call: Call) -> _Value: ...

    @abstractmethod
    def _none(self, call: Call) -> _None: ...

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
                self.lease = None
            raise error
        if call.lease == "grant":
            self.lease = Lease.from_json(body)
        elif call.lease == "drop":
            self.lease = None
        if call.control and self.lease is not None:
            self._renewed_at = self._now()
        return body[call.pick] if call.pick is not None else body

    def _renew_due(self) -> bool:
        """A wait renews a held lease at a third of its TTL, so waiting never loses it."""
        return self.lease is not None and self._now() - self._renewed_at > self.lease.ttl_s / 3

    def _vehicle(self, path: str = "") -> str:
        return f"/vehicles/{self.vehicle_id}{path}"

    def _op(self, path: str, body: Any = None, method: str = "POST") -> Call:
        return Call(method, self._vehicle(path), body, control=True)

    # -- reads ------------------------------------------------------------------------

    def health(self) -> _Json:
        return self._json(Call("GET", "/health"))

    def vehicles(self) -> _Json:
        """Every vehicle served: ``[{id, sysid, type, autopilot, connected, mode, armed,
        link}]``."""
        return self._json(Call("GET", "/vehicles"))

    def state(self) -> _State:
        return self._state(Call("GET", self._vehicle()))

    def stream_stats(self) -> _Json:
        return self._json(Call("GET", self._vehicle("/stream")))

    # -- control ----------------------------------------------------------------------

    def acquire(self, *, ttl_s: float | None = None, client_name: str | None = None) -> _Lease:
        """Take the control lease (409 :class:`Refused` naming the holder while someone else
        has it); ``ttl_s`` within the server's bounds, its default otherwise."""
        body = _given(ttl_s=ttl_s, client_name=client_name)
        return self._lease(
            Call("POST", self._vehicle("/control"), body, control=True, lease="grant")
        )

    def take_over(
        self, *, force: bool = False, ttl_s: float | None = None, client_name: str | None = None
    ) -> _Lease:
        """Ask the holder for control (granted: the lease; denied or unanswered: 409), or
        with ``force`` take it at once."""
        body = _given(takeover=True, force=force or None, ttl_s=ttl_s, client_name=client_name)
        return self._lease(
            Call("POST", self._vehicle("/control"), body, control=True, lease="grant")
        )

    def renew(self, *, ttl_s: float | None = None, client_name: str | None = None) -> _Lease:
        """Renew the lease (any control call also does), optionally with a new TTL or
        label."""
        body = _given(ttl_s=ttl_s, client_name=client_name) or None
        return self._lease(
            Call("PUT", self._vehicle("/control"), body, control=True, lease="grant")
        )

    def control_status(self) -> _Json:
        """Who holds control: ``{holder, session, since_s, expires_in_s, ttl_s, request}``;
        ``request`` is a pending takeover (``request_id``, ``by``) the holder may answer."""
        return self._json(Call("GET", self._vehicle("/control")))

    def release(self) -> _None:
        return self._none(Call("DELETE", self._vehicle("/control"), control=True, lease="drop"))

    def answer_takeover(self, request_id: str, *, grant: bool) -> _Json:
        """The holder's answer to a ``takeover_requested`` control event."""
        path = self._vehicle(f"/control/requests/{request_id}")
        return self._json(Call("POST", path, {"grant": grant}, control=True))

    def audit(self, *, limit: int = 100) -> _Json:
        params = {"vehicle": str(self.vehicle_id), "limit": str(limit)}
        return self._json(Call("GET", "/control/audit", params=params))

    # -- commands ---------------------------------------------------------------------

    def arm(self, *, force: bool = False) -> _Cmd:
        return self._command(self._op("/arm", {"force": force}))

    def disarm(self, *, force: bool = False) -> _Cmd:
        return self._command(self._op("/disarm", {"force": force}))

    def takeoff(self, *, altitude_m: float | None = None) -> _Cmd:
        """Climb to ``altitude_m`` above home (default: the vehicle's MIS_TAKEOFF_ALT)."""
        return self._command(self._op("/takeoff", _given(altitude_m=altitude_m)))

    def land(self) -> _Cmd:
        return self._command(self._op("/land"))

    def rtl(self) -> _Cmd:
        return self._command(self._op("/rtl"))

    def hold(self) -> _Cmd:
        return self._command(self._op("/hold"))

    def set_mode(self, mode: str) -> _Cmd:
        """A PX4 mode by name (``"OFFBOARD"``, ``"POSCTL"``, ...), confirmed by the vehicle."""
        return self._command(self._op("/mode", {"mode": mode}))

    def reposition(
        self,
        *,
        lat_deg: float,
        lon_deg: float,
        alt_amsl_m: float | None = None,
        alt_rel_m: float | None = None,
        ground_speed_m_s: float | None = None,
        yaw_deg: float | None = None,
        loiter_radius_m: float | None = None,
    ) -> _Cmd:
        body = _given(
            lat_deg=lat_deg,
            lon_deg=lon_deg,
            alt_amsl_m=alt_amsl_m,
            alt_rel_m=alt_rel_m,
            ground_speed_m_s=ground_speed_m_s,
            yaw_deg=yaw_deg,
            loiter_radius_m=loiter_radius_m,
        )
        return self._command(self._op("/reposition", body))

    def vtol_transition(
        self,
        to: Literal["fixed_wing", "multicopter"],
        *,
        immediate: bool = False,
        wait: bool = True,
    ) -> _Cmd:
        body = {"to": to, "immediate": immediate, "wait": wait}
        return self._command(self._op("/vtol/transition", body))

    def set_origin(self, *, lat_deg: float, lon_deg: float, alt_amsl_m: float) -> _Cmd:
        body = {"lat_deg": lat_deg, "lon_deg": lon_deg, "alt_amsl_m": alt_amsl_m}
        return self._command(self._op("/origin", body))

    def set_home(
        self,
        *,
        lat_deg: float | None = None,
        lon_deg: float | None = None,
        alt_amsl_m: float | None = None,
    ) -> _Cmd:
        """Home at the point given, or where the vehicle is without one."""
        body = _given(lat_deg=lat_deg, lon_deg=lon_deg, alt_amsl_m=alt_amsl_m)
        return self._command(self._op("/home", body))

    def offboard_start(self, setpoint: SetpointKind | Mapping[str, Any] | None = None) -> _Cmd:
        """Stream ``setpoint`` (default: hold here) and switch to OFFBOARD."""
        body = {"setpoint": setpoint_json(setpoint)} if setpoint is not None else {}
        return self._command(self._op("/offboard/start", body))

    def offboard_stop(self, *, then_mode: str = "HOLD") -> _Cmd:
        return self._command(self._op("/offboard/stop", {"then_mode": then_mode}))

    # -- setpoints and intents --------------------------------------------------------

    def set_setpoint(
        self, setpoint: SetpointKind | Mapping[str, Any], *, live: bool = False
    ) -> _Json:
        """Replace the streamed setpoint; ``live`` ones (hold-to-fly input) are braked by the
        deadman when no update follows in time. Answers what is sent:
        ``{setpoint, message, frame, type_mask}``."""
        call = self._op("/setpoint", setpoint_json(setpoint), method="PUT")
        if live:
            call = Call(call.method, call.path, call.body, {"live": "true"}, control=True)
        return self._json(call)

    def brake(self) -> _Json:
        """Brake, then hold where the vehicle stops (HOLD mode when not streaming). Answers
        ``{intent, via, setpoint, command, target, live}``, as every intent does."""
        return self._json(self._op("/intents/brake"))

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
    ) -> _Json:
        """Fly at a velocity: forward/right in the body frame or north/east, ``up_m_s``
        positive up, ``yaw_rate_deg_s`` clockwise seen from above (``hold_altitude``: keep
        the altitude instead). Live input by default: without a new call within the
        server's deadman timeout the vehicle brakes and holds; ``live=False`` flies it until
        replaced. Needs OFFBOARD (``offboard_start``) to fly."""
        body = _given(
            forward_m_s=forward_m_s,
            right_m_s=right_m_s,
            north_m_s=north_m_s,
            east_m_s=east_m_s,
            up_m_s=up_m_s,
            yaw_rate_deg_s=yaw_rate_deg_s,
        )
        body.update(frame=frame, hold_altitude=hold_altitude, live=live)
        return self._json(self._op("/intents/velocity", body, "PUT"))

    def offset(
        self,
        *,
        north_m: float = 0.0,
        east_m: float = 0.0,
        up_m: float = 0.0,
        yaw_deg: float | None = None,
    ) -> _Json:
        """Go by an offset from where the vehicle is (checked against the envelope)."""
        body = _given(north_m=north_m, east_m=east_m, up_m=up_m, yaw_deg=yaw_deg)
        return self._json(self._op("/intents/offset", body))

    def goto(
        self,
        *,
        lat_deg: float,
        lon_deg: float,
        alt_rel_m: float | None = None,
        yaw_deg: float | None = None,
    ) -> _Json:
        """Go to a point, ``alt_rel_m`` above home (default: the current altitude)."""
        body = _given(lat_deg=lat_deg, lon_deg=lon_deg, alt_rel_m=alt_rel_m, yaw_deg=yaw_deg)
        return self._json(self._op("/intents/goto", body))

    # -- parameters -------------------------------------------------------------------

    def params(self, *names: str) -> _Json:
        """``{name: value}`` for the names given, or every parameter."""
        params = {"names": ",".join(names)} if names else {}
        return self._json(Call("GET", self._vehicle("/params"), params=params, pick="params"))

    def param(self, name: str) -> _Value:
        return self._value(Call("GET", self._vehicle(f"/params/{name}"), pick="value"))

    def set_param(self, name: str, value: float) -> _Value:
        """Set a parameter; answers the value the vehicle echoed."""
        call = Call(
            "PUT", self._vehicle(f"/params/{name}"), {"value": value}, control=True, pick="value"
        )
        return self._value(call)
