"""A stand-in edge for the fleet server's in-process tests: a plain Zenoh session that
publishes what fleet-spec says an edge publishes, and answers api queries with what the test
tells it (recording each query), on loopback only with explicit endpoints."""

from __future__ import annotations

import json
import socket
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import zenoh

from server.fleet.keys import FleetKeys
from server.fleet.session import ZenohOptions, open_session


def free_tcp_endpoint() -> str:
    """A Zenoh endpoint on a loopback port that was free a moment ago (Zenoh cannot tell
    which port it got for :0, so peers could not be told where to connect)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{probe.getsockname()[1]}"


def loopback_options(
    listen: list[str] | None = None, connect: list[str] | None = None, mode: str = "peer"
) -> ZenohOptions:
    if mode == "peer" and not listen:
        # a peer listens somewhere: on loopback, not Zenoh's default of every interface
        listen = [free_tcp_endpoint()]
    return ZenohOptions(
        mode=mode,  # type: ignore[arg-type]
        listen=listen or [],
        connect=connect or [],
        multicast_scouting=False,
    )


@dataclass
class FakeEdge:
    keys: FleetKeys
    name: str
    session: zenoh.Session
    # what the api queryable answers; "silent" = never answers (the query times out)
    answer: dict[str, Any] | str = field(default_factory=lambda: {"status": 200, "body": {}})
    queries: list[dict[str, Any]] = field(default_factory=list)
    tokens: dict[int | None, zenoh.LivelinessToken] = field(default_factory=dict)
    listen: list[str] = field(default_factory=list)
    seq: int = 0
    _lock: threading.Lock = field(default_factory=threading.Lock)

    @classmethod
    def open(cls, keys: FleetKeys, name: str, options: ZenohOptions) -> FakeEdge:
        edge = cls(keys, name, open_session(options), listen=list(options.listen))
        edge.session.declare_queryable(keys.api(name), zenoh.handlers.Callback(edge._on_query))
        edge.tokens[None] = edge.session.liveliness().declare_token(keys.edge_alive(name))
        return edge

    def _on_query(self, query: zenoh.Query) -> None:
        payload = query.payload
        request = json.loads(payload.to_bytes()) if payload is not None else None
        with self._lock:
            self.queries.append(request)
            answer = self.answer
        if answer == "silent":
            return  # dropped unanswered: the querier hears of it only by its timeout
        query.reply(query.key_expr, json.dumps(answer).encode())

    def vehicle_up(self, vehicle_id: int) -> None:
        self.tokens[vehicle_id] = self.session.liveliness().declare_token(
            self.keys.vehicle_alive(self.name, vehicle_id)
        )

    def vehicle_down(self, vehicle_id: int) -> None:
        self.tokens.pop(vehicle_id).undeclare()

    def publish_state(self, vehicle_id: int, state: dict[str, Any]) -> None:
        self.seq += 1
        payload = {
            "edge": self.name, "id": vehicle_id, "seq": self.seq,
            "sent_unix_s": time.time(), "state": state,
        }
        self.session.put(self.keys.state(self.name, vehicle_id, "fast"), json.dumps(payload))

    def publish_event(self, vehicle_id: int, event: dict[str, Any]) -> None:
        self.session.put(
            self.keys.events(self.name, vehicle_id),
            json.dumps({**event, "edge": self.name, "id": vehicle_id}),
        )

    def close(self) -> None:
        self.session.close()
