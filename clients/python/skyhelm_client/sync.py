"""The blocking client: each call returns when the server answered."""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Generator
from typing import Any, TypeVar

import httpx
from pydantic import BaseModel
from websockets.sync.client import connect

from skyhelm_client.calls import Call, Waiting, json_body
from skyhelm_client.errors import SkyHelmError
from skyhelm_client.generated import SyncCalls
from skyhelm_client.models import (
    Answer,
    CommandResult,
    Lease,
    Message,
    ParamValues,
    State,
    param_value,
    param_values,
)
from skyhelm_client.tls import default_tls
from skyhelm_client.urls import ws_url
from skyhelm_wire.control import AuditEntryOut
from skyhelm_wire.intents import IntentOut
from skyhelm_wire.setpoints import SentSetpointOut

_M = TypeVar("_M", bound=BaseModel)


class SkyHelm(SyncCalls):
    """One vehicle of a SkyHelm server, over REST (and the telemetry WebSocket)::

        with SkyHelm("http://127.0.0.1:8000/?token=...") as sky:
            sky.acquire(ttl_s=120)
            sky.arm()
            sky.takeoff(altitude_m=5)
            sky.wait_until(lambda s: s.altitude_m > 4.5, timeout_s=60)

    Refusals raise :class:`~skyhelm_client.errors.SkyHelmError` subclasses."""

    # what waits measure time with
    clock: Callable[[], float] = time.monotonic
    _http: httpx.Client

    def _open(self, timeout_s: float) -> None:
        self._http = httpx.Client(timeout=timeout_s, verify=default_tls())

    def __enter__(self) -> SkyHelm:
        return self

    def __exit__(self, *exc_info: object) -> None:
        try:
            if self.lease is not None:
                self.release()
        except SkyHelmError:
            pass  # lapsed or taken over meanwhile: nothing left to give back
        finally:
            self.close()

    def close(self) -> None:
        self._http.close()

    def _send(self, call: Call) -> tuple[int, Any]:
        try:
            response = self._http.request(**self._request(call))
        except httpx.HTTPError as exc:
            raise SkyHelmError(0, f"{call.method} {call.path}: {exc}") from exc
        return response.status_code, self._answer(call, response.status_code, json_body(response))

    def _command(self, call: Call) -> CommandResult:
        status, body = self._send(call)
        return CommandResult.from_json(body, status)

    def _lease(self, call: Call) -> Lease:
        return Lease.from_json(self._send(call)[1])

    def _state(self, call: Call) -> State:
        return State(self._send(call)[1])

    def _typed(self, call: Call, model: type[_M]) -> Answer[_M]:
        return Answer(self._send(call)[1], model)

    def _typed_list(self, call: Call, model: type[_M]) -> list[Answer[_M]]:
        return [Answer(item, model) for item in self._send(call)[1]]

    def _json(self, call: Call) -> Any:
        return self._send(call)[1]

    def _bytes(self, call: Call) -> bytes:
        return bytes(self._send(call)[1])

    def _value(self, call: Call) -> float | None:
        return param_value(self._send(call)[1])

    def _none(self, call: Call) -> None:
        self._send(call)

    def _intent(self, call: Call) -> Answer[IntentOut]:
        return Answer(self._send(call)[1], IntentOut)

    def _sent(self, call: Call) -> Answer[SentSetpointOut]:
        return Answer(self._send(call)[1], SentSetpointOut)

    def _params(self, call: Call) -> ParamValues:
        return param_values(self._send(call)[1])

    def _audit(self, call: Call) -> list[Answer[AuditEntryOut]]:
        return self._typed_list(call, AuditEntryOut)

    def _now(self) -> float:
        return self.clock()

    def _wait(self, waiting: Waiting, poll_s: float) -> State:
        while True:
            state = self._renewed_state()
            if waiting.met(state):
                return state
            time.sleep(poll_s)

    def _renewed_state(self) -> State:
        if self._renew_due():
            self.renew()
        return self.state()

    def telemetry(
        self, *, rate_hz: float = 10.0, all_vehicles: bool = False
    ) -> Generator[Message, None, None]:
        """The telemetry socket's messages as they come (states latest-wins at ``rate_hz``,
        events, statustexts); the socket closes when the iteration stops."""
        url = ws_url(self.base_url, self.token, None if all_vehicles else self.vehicle_id, rate_hz)
        with connect(url) as ws:
            for text in ws:
                data = json.loads(text)
                yield Message(str(data.get("type")), data)

    def states(self, *, rate_hz: float = 10.0) -> Generator[State, None, None]:
        """Only the state snapshots of the telemetry socket."""
        for message in self.telemetry(rate_hz=rate_hz):
            if message.state is not None:
                yield message.state
