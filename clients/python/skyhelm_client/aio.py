"""The asyncio client: every call is awaited; telemetry is an async iterator."""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncGenerator
from typing import Any, TypeVar

import httpx
from pydantic import BaseModel
from websockets.asyncio.client import connect

from skyhelm_client.calls import Call, Waiting, json_body
from skyhelm_client.errors import SkyHelmError
from skyhelm_client.generated import AsyncCalls
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


class AsyncSkyHelm(AsyncCalls):
    """One vehicle of a SkyHelm server, for asyncio::

        async with AsyncSkyHelm("http://127.0.0.1:8000/?token=...") as sky:
            await sky.acquire(ttl_s=120)
            await sky.arm()
            async for message in sky.telemetry():
                ...

    The same calls as :class:`~skyhelm_client.SkyHelm`, awaited."""

    _http: httpx.AsyncClient

    def _open(self, timeout_s: float) -> None:
        self._http = httpx.AsyncClient(timeout=timeout_s, verify=default_tls())

    async def __aenter__(self) -> AsyncSkyHelm:
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        try:
            if self.lease is not None:
                await self.release()
        except SkyHelmError:
            pass  # lapsed or taken over meanwhile: nothing left to give back
        finally:
            await self.aclose()

    async def aclose(self) -> None:
        await self._http.aclose()

    async def _send(self, call: Call) -> tuple[int, Any]:
        try:
            response = await self._http.request(**self._request(call))
        except httpx.HTTPError as exc:
            raise SkyHelmError(0, f"{call.method} {call.path}: {exc}") from exc
        return response.status_code, self._answer(call, response.status_code, json_body(response))

    async def _command(self, call: Call) -> CommandResult:
        status, body = await self._send(call)
        return CommandResult.from_json(body, status)

    async def _lease(self, call: Call) -> Lease:
        return Lease.from_json((await self._send(call))[1])

    async def _state(self, call: Call) -> State:
        return State((await self._send(call))[1])

    async def _typed(self, call: Call, model: type[_M]) -> Answer[_M]:
        return Answer((await self._send(call))[1], model)

    async def _typed_list(self, call: Call, model: type[_M]) -> list[Answer[_M]]:
        return [Answer(item, model) for item in (await self._send(call))[1]]

    async def _json(self, call: Call) -> Any:
        return (await self._send(call))[1]

    async def _bytes(self, call: Call) -> bytes:
        return bytes((await self._send(call))[1])

    async def _value(self, call: Call) -> float | None:
        return param_value((await self._send(call))[1])

    async def _none(self, call: Call) -> None:
        await self._send(call)

    async def _intent(self, call: Call) -> Answer[IntentOut]:
        return Answer((await self._send(call))[1], IntentOut)

    async def _sent(self, call: Call) -> Answer[SentSetpointOut]:
        return Answer((await self._send(call))[1], SentSetpointOut)

    async def _params(self, call: Call) -> ParamValues:
        return param_values((await self._send(call))[1])

    async def _audit(self, call: Call) -> list[Answer[AuditEntryOut]]:
        return await self._typed_list(call, AuditEntryOut)

    def _now(self) -> float:
        return asyncio.get_running_loop().time()

    async def _wait(self, waiting: Waiting, poll_s: float) -> State:
        while True:
            state = await self._renewed_state()
            if waiting.met(state):
                return state
            await asyncio.sleep(poll_s)

    async def _renewed_state(self) -> State:
        if self._renew_due():
            await self.renew()
        return await self.state()

    async def telemetry(
        self, *, rate_hz: float = 10.0, all_vehicles: bool = False
    ) -> AsyncGenerator[Message, None]:
        """The telemetry socket's messages as they come (states latest-wins at ``rate_hz``,
        events, statustexts); the socket closes when the iteration stops (use
        ``contextlib.aclosing`` to close it at once after a ``break``)."""
        url = ws_url(self.base_url, self.token, None if all_vehicles else self.vehicle_id, rate_hz)
        async with connect(url) as ws:
            async for text in ws:
                data = json.loads(text)
                yield Message(str(data.get("type")), data)

    async def states(self, *, rate_hz: float = 10.0) -> AsyncGenerator[State, None]:
        """Only the state snapshots of the telemetry socket."""
        async for message in self.telemetry(rate_hz=rate_hz):
            if message.state is not None:
                yield message.state
