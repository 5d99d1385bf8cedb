"""MAVLink 2 signing: its state on every link, and setting, rotating or removing the key.

The key is the server's (one per server, in ``signing_key_file``), made by the server and
never shown. Setting it sends SETUP_SIGNING to every vehicle, as PX4 documents, switches
each link, and answers once every vehicle talks with the new key (504 if one never does:
the links then keep their previous key). PX4 refuses SETUP_SIGNING while armed, so an
armed vehicle makes it a 409 before anything is sent."""

from __future__ import annotations

import asyncio
import contextlib

from fastapi import APIRouter, Request

from server.http.deps import Context, Pilot, Reader
from server.http.errors import AUTH_RESPONSES, ApiError
from server.http.routing import route
from server.link import Link
from server.link.codec.signing_keys import SigningKeyStore, new_key
from server.link.codec.signing_provision import ProvisionError, provision
from skyhelm_wire.calls import API_PREFIX, CALL
from skyhelm_wire.common import ErrorOut
from skyhelm_wire.signing import (
    LinkSigningOut,
    SigningBody,
    SigningOut,
    SigningStatusOut,
)

router = APIRouter(prefix=API_PREFIX, tags=["signing"])

_RESPONSES: dict[int | str, dict[str, object]] = {
    **AUTH_RESPONSES,
    403: {"model": ErrorOut,
          "description": "observer tokens may only read; a replay is read-only"},
    409: {"model": ErrorOut,
          "description": "refused: no signing_key_file, a vehicle is armed, no vehicle, or "
                         "the action does not fit (generate while on, rotate while off)"},
    504: {"model": ErrorOut,
          "description": "a vehicle never answered with the new key; the old key is kept"},
}


def _store(request: Request) -> SigningKeyStore | None:
    store: SigningKeyStore | None = request.app.state.signing_store
    return store


def _status(context: Context, store: SigningKeyStore | None) -> SigningStatusOut:
    links = []
    for link in context.registry.links:
        stats = link.stats().signing
        if stats is not None:
            links.append(LinkSigningOut(
                url=link.url, vehicles=sorted(link.vehicles),
                signing=SigningOut.model_validate(stats, from_attributes=True),
            ))  # fmt: skip
    return SigningStatusOut(
        enabled=store is not None and store.key is not None,
        key_file_set=store is not None,
        links=links,
    )


@route(router, CALL["signing_status"], responses=AUTH_RESPONSES)
async def signing_status(request: Request, context: Context, _: Reader) -> SigningStatusOut:
    return _status(context, _store(request))


@route(router, CALL["set_signing"], responses=_RESPONSES)
async def set_signing(
    request: Request, body: SigningBody, context: Context, _: Pilot
) -> SigningStatusOut:
    """Set (generate), replace (rotate) or remove (disable) the MAVLink signing key."""
    store = _store(request)
    if store is None:
        raise ApiError(409, "signing_key_file is not set: a key the server cannot keep would "
                            "lock it out of its vehicles after a restart")
    async with store.lock:
        enabled = store.key is not None
        if body.action == "generate" and enabled:
            raise ApiError(409, "signing is already on; rotate replaces the key")
        if body.action != "generate" and not enabled:
            raise ApiError(409, f"signing is off; nothing to {body.action}")
        targets = _targets(context)
        key = None if body.action == "disable" else new_key()
        old_key = store.key
        # first: a crash mid-way must not leave the file behind (fsync: off the loop)
        await asyncio.to_thread(store.replace_key, key)
        done: list[Link] = []
        try:
            for link, sysids in targets:
                await provision(link, sysids, key)
                done.append(link)
        except ProvisionError as exc:
            for link in done:  # best effort: back to the key the file keeps again
                with contextlib.suppress(ProvisionError):
                    await provision(link, sorted(link.vehicles), old_key)
            await asyncio.to_thread(store.replace_key, old_key)
            raise ApiError(504, str(exc)) from None
    return _status(context, store)


def _targets(context: Context) -> list[tuple[Link, list[int]]]:
    """Each link with its vehicles; 409 if one is armed or none is connected."""
    targets = []
    for link in context.registry.links:
        vehicles = [v for v in link.vehicles.values() if v.connected]
        for vehicle in vehicles:
            if vehicle.snapshot().armed:
                raise ApiError(409, f"vehicle {vehicle.sysid} is armed: PX4 rejects "
                                    "SETUP_SIGNING while armed")
        if vehicles:
            targets.append((link, sorted(v.sysid for v in vehicles)))
    if not targets:
        raise ApiError(409, "no connected vehicle to give the key to")
    return targets
