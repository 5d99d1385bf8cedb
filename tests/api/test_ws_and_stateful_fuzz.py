"""Fuzz what tests/api/test_openapi_fuzz.py does not reach: the control WebSocket's messages
(hypothesis-generated, over a real uvicorn, flying the simulated quad) and schemathesis's
stateful workflows over the OpenAPI links (vehicle ids from GET /vehicles into every
operation, a parameter read into its write) against `skyhelm serve` as a user starts it.
No message or call may be answered with a 5xx, and the server keeps answering."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import httpx
import schemathesis
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from schemathesis.checks import not_a_server_error
from websockets.asyncio.client import connect

from server.control.operations import INTENT_NAMES, OPERATIONS
from tests.api.test_ws import receive, served
from tests.serve_process import skyhelm_serve

WS_MESSAGES = 160
STATEFUL_EXAMPLES = 25
STATEFUL_STEPS = 8
# Commands whose failure path waits out a vehicle timeout (no ack on a quad) or would fly
# the vehicle away from the fuzz: the REST fuzz and the flight tests cover them.
_SLOW_COMMANDS = frozenset({"vtol_transition"})

_numbers = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.sampled_from([0, -1, 1e308, -1e308, 5e-324, 2**53 + 1]),
)
_json_scalars = st.one_of(st.none(), st.booleans(), _numbers, st.text(max_size=20))
_json = st.recursive(
    _json_scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=4),
                            st.dictionaries(st.text(max_size=12), inner, max_size=4)),
    max_leaves=12,
)
_setpoint_kinds = ["position_ned", "velocity_ned", "velocity_body", "position_global",
                   "attitude", "offset_body", "hold", "nope"]
_setpoint_fields = ["north_m", "east_m", "down_m", "yaw_deg", "north_m_s", "east_m_s",
                    "down_m_s", "forward_m_s", "right_m_s", "lat_deg", "lon_deg",
                    "alt_amsl_m", "roll_deg", "pitch_deg", "thrust", "yaw_rate_deg_s"]
_setpoints = st.one_of(
    _json,
    st.fixed_dictionaries(
        {"type": st.sampled_from(_setpoint_kinds)},
        optional={name: st.one_of(_numbers, _json_scalars) for name in _setpoint_fields},
    ),
)
_command_names = st.one_of(
    st.sampled_from(sorted(set(OPERATIONS) - _SLOW_COMMANDS) + sorted(INTENT_NAMES)),
    _json_scalars,
)
_messages = st.one_of(
    st.fixed_dictionaries({"type": st.just("heartbeat")}, optional={"extra": _json}),
    st.fixed_dictionaries({"type": st.just("setpoint"), "setpoint": _setpoints},
                          optional={"live": st.one_of(st.booleans(), _json_scalars)}),
    st.fixed_dictionaries({"type": st.just("command"), "name": _command_names},
                          optional={"args": st.one_of(_json, st.dictionaries(
                              st.sampled_from(["altitude_rel_m", "mode", "force", "north_m",
                                               "east_m", "down_m", "yaw_deg", "speed_m_s",
                                               "lat_deg", "lon_deg", "alt_amsl_m"]),
                              st.one_of(_numbers, _json_scalars), max_size=4))}),
    st.fixed_dictionaries({"type": st.just("takeover_answer")},
                          optional={"request_id": _json_scalars, "grant": _json_scalars}),
    st.dictionaries(st.text(max_size=10), _json, max_size=4),
)


def generate_ws_messages(count: int) -> list[str]:
    """JSON texts (and a few that are not JSON, or not objects), generated up front."""
    texts: list[str] = []

    @settings(max_examples=count, derandomize=True, database=None, phases=[Phase.generate],
              suppress_health_check=list(HealthCheck), deadline=None)
    @given(_messages, st.integers(min_value=0, max_value=9))
    def collect(message: dict[str, Any], shape: int) -> None:
        if shape == 0:
            texts.append(json.dumps(message)[: max(1, len(texts) % 17)])  # cut short
        elif shape == 1:
            texts.append(json.dumps([message]))
        else:
            texts.append(json.dumps({**message, "id": len(texts)}))

    collect()
    return texts


async def test_control_socket_messages_never_get_a_5xx_and_the_socket_lives_on() -> None:
    texts = generate_ws_messages(WS_MESSAGES)
    assert len(texts) >= WS_MESSAGES
    started = time.monotonic()
    async with served(deadman_timeout_s=10.0) as quad:
        vehicle = quad.api.app.state.api.registry.get(1)
        vehicle.mode_confirm_timeout_s = 0.3
        answers: list[dict[str, Any]] = []
        async with connect(quad.url("control", vehicle=1, ttl_s=60)) as ws:
            for text in texts:
                await ws.send(text)
                # every message is answered (by id, or with id null when it has none)
                while True:
                    reply = await receive(ws, 15.0)
                    if reply.get("type") == "result":
                        answers.append(reply)
                        break
            heartbeat_id = "still-there"
            await ws.send(json.dumps({"type": "heartbeat", "id": heartbeat_id}))
            while (reply := await receive(ws, 15.0)).get("id") != heartbeat_id:
                pass
            assert reply["status"] == 200
        async with httpx.AsyncClient(base_url=f"http://{quad.host}") as client:
            health = await client.get("/api/v1/health")
            assert health.status_code == 200
    server_errors = [a for a in answers if a["status"] >= 500]
    assert not server_errors, server_errors[:5]
    statuses = sorted({a["status"] for a in answers})
    assert {200, 422} <= set(statuses), statuses
    print(f"ws fuzz: {len(texts)} messages, statuses {statuses}, "
          f"{time.monotonic() - started:.1f} s")


def test_stateful_workflows_over_the_openapi_links_find_no_5xx(tmp_path: Path) -> None:
    calls: list[tuple[str, int]] = []
    with skyhelm_serve(tmp_path) as server:
        headers = {"Authorization": f"Bearer {server.pilot_token}"}
        with httpx.Client(base_url=server.base_url, headers=headers, timeout=30.0) as http:

            def vehicle_up() -> bool:
                return bool(http.get("/api/v1/vehicles").json())

            deadline = time.monotonic() + 60.0
            while not vehicle_up():
                assert time.monotonic() < deadline, "no vehicle"
                time.sleep(0.2)
            schema = schemathesis.openapi.from_dict(http.get("/openapi.json").json())
            schema.config.update(base_url=server.base_url)
            workflow = schema.as_state_machine()

            class Workflow(workflow):  # type: ignore[misc, valid-type]
                def get_call_kwargs(self, case: Any) -> dict[str, Any]:
                    call_headers = dict(headers)
                    lease = _lease_of(http, case)
                    if lease is not None:
                        call_headers["X-Lease-Id"] = lease
                    return {"headers": call_headers, "timeout": 30.0}

                def validate_response(self, response: Any, case: Any, **kwargs: Any) -> None:
                    calls.append((case.operation.label, response.status_code))
                    if _vehicle_never_answered(case, response):
                        return  # the documented 504: PX4 ignores unknown parameter names
                    case.validate_response(response, checks=[not_a_server_error])

            started = time.monotonic()
            Workflow.run(settings=settings(
                max_examples=STATEFUL_EXAMPLES, stateful_step_count=STATEFUL_STEPS,
                derandomize=True, database=None, deadline=None,
                suppress_health_check=list(HealthCheck), phases=[Phase.generate],
            ))
            assert http.get("/api/v1/health").status_code == 200
    operations = {label for label, _ in calls}
    print(f"stateful: {len(calls)} calls over {len(operations)} operations in "
          f"{time.monotonic() - started:.1f} s")
    assert len(calls) >= STATEFUL_EXAMPLES
    assert all(status < 500 or status == 504 for _, status in calls)


def _vehicle_never_answered(case: Any, response: Any) -> bool:
    """A 504 of a parameter the vehicle never answered for (docs/api.md: 504 when the
    vehicle answers neither the name nor its whole list, which tells a name it does not
    have, 404, from silence)."""
    if response.status_code != 504 or "/params" not in case.operation.path:
        return False
    return any(text in response.text for text in (
        "no answer for parameter", "no answer to PARAM_REQUEST_LIST", "parameters still missing"))


def _lease_of(http: httpx.Client, case: Any) -> str | None:
    """The pilot's lease on the case's vehicle, taken when nobody holds it, so that control
    calls get past the lease to the vehicle (the workflow may release it at any step)."""
    vehicle_id = (case.path_parameters or {}).get("vehicle_id")
    if not isinstance(vehicle_id, int) or vehicle_id != 1:
        return None
    response = http.post("/api/v1/vehicles/1/control", json={})
    lease = response.headers.get("X-Lease-Id")
    if lease is None and response.status_code == 200:
        lease = response.json().get("lease_id")
    return lease
