"""The deployment files of docker/: the fleet compose file's commands are commands SkyHelm
accepts, and the Zenoh TLS + access-control example really keeps a stranger out."""

from __future__ import annotations

import importlib.util
import json
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import trustme
import yaml
import zenoh

from server.cli import build_parser, settings_from_args
from server.fleet.keys import FleetKeys
from server.fleet.router import RouterOptions, router_config
from server.fleet.session import ZenohOptions, zenoh_config
from tests.waiting import holds_for_blocking, wait_for_blocking

DOCKER = Path(__file__).resolve().parents[2] / "docker"
COMPOSE = DOCKER / "fleet.compose.yaml"


def services() -> dict[str, Any]:
    loaded: dict[str, Any] = yaml.safe_load(COMPOSE.read_text())
    return loaded["services"]


def _run_fleet_locally() -> Any:
    spec = importlib.util.spec_from_file_location("run_fleet_locally",
                                                  DOCKER / "run_fleet_locally.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("observer", [None, "an-observer-token-long-enough"])
def test_the_fleet_compose_has_a_router_two_edges_and_a_fleet_server(
    monkeypatch: pytest.MonkeyPatch, observer: str | None,
) -> None:
    compose_environment = _run_fleet_locally().compose_environment
    host = {"SKYHELM_TOKEN": "a-pilot-token-long-enough-for-the-checks"}
    if observer is not None:
        host["SKYHELM_OBSERVER_TOKEN"] = observer
    roles: dict[str, list[str]] = {"router": [], "edge": [], "fleet": []}
    edge_names = []
    for name, service in services().items():
        args = build_parser().parse_args(service["command"])
        if args.command == "router":
            roles["router"].append(name)
            assert args.listen == ["tcp/0.0.0.0:7447"]
            continue
        # the service's environment as compose gives it, and nothing else of SkyHelm's
        for variable in [v for v in os.environ if v.startswith("SKYHELM_")]:
            monkeypatch.delenv(variable)
        for variable, value in compose_environment(service, host).items():
            monkeypatch.setenv(variable, value)
        settings = settings_from_args(args)
        given = settings.observer_token
        assert (given.get_secret_value() if given is not None else None) == observer
        # everything meets at the router, by name on the compose network
        assert settings.zenoh_mode == "client"
        assert settings.zenoh_connect == ["tcp/router:7447"]
        assert not settings.zenoh_multicast_scouting
        assert settings.fleet_name == "default"
        assert service["depends_on"] == ["router"]
        if settings.fleet:
            roles["fleet"].append(name)
            assert not settings.connect, "the fleet server flies the edges' vehicles"
        else:
            assert settings.zenoh, f"{name} must publish to the fleet"
            assert not settings.connect, "each edge flies its own simulated vehicle"
            roles["edge"].append(name)
            edge_names.append(settings.edge_name)
    assert roles == {"router": ["router"], "edge": ["edge-a", "edge-b"], "fleet": ["fleet"]}
    assert edge_names == ["edge-a", "edge-b"]


def test_the_zenoh_examples_are_valid_configurations() -> None:
    for path in sorted((DOCKER / "zenoh").glob("*.json5")):
        config = zenoh.Config.from_file(str(path))
        assert config.get_json("transport/link/tls/enable_mtls") == "true", path


# ---- mutual TLS and access control, from docker/zenoh/router-tls-acl.json5 ----------------

@pytest.fixture(scope="module")
def certificates(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("certs")
    ca = trustme.CA()
    ca.cert_pem.write_to_path(str(folder / "ca.pem"))
    for name in ("router", "edge-a", "fleet", "stranger"):
        leaf = ca.issue_cert("localhost", "127.0.0.1", common_name=name)
        leaf.cert_chain_pems[0].write_to_path(str(folder / f"{name}.pem"))
        leaf.private_key_pem.write_to_path(str(folder / f"{name}-key.pem"))
    return folder


def _paths(config: zenoh.Config, certs: Path, side: str, name: str) -> None:
    config.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(certs / "ca.pem")))
    config.insert_json5(f"transport/link/tls/{side}_certificate",
                        json.dumps(str(certs / f"{name}.pem")))
    config.insert_json5(f"transport/link/tls/{side}_private_key",
                        json.dumps(str(certs / f"{name}-key.pem")))


@pytest.fixture(scope="module")
def tls_router(certificates: Path) -> Iterator[str]:
    config, listen = router_config(RouterOptions(
        listen=["tls/127.0.0.1:0"], config_file=DOCKER / "zenoh" / "router-tls-acl.json5",
    ))
    _paths(config, certificates, "listen", "router")
    with zenoh.open(config):
        yield listen[0].replace("127.0.0.1", "localhost")


def _member(endpoint: str, certs: Path, name: str) -> zenoh.Session:
    config = zenoh_config(ZenohOptions(
        mode="client", connect=[endpoint], multicast_scouting=False,
        config_file=DOCKER / "zenoh" / "member-tls.json5",
    ))
    _paths(config, certs, "connect", name)
    return zenoh.open(config)


def test_a_certificate_outside_the_access_list_reads_and_writes_nothing(
    tls_router: str, certificates: Path,
) -> None:
    keys = FleetKeys("default")
    state_key = keys.state("edge-a", 1, "fast")
    fleet_got: list[bytes] = []
    stranger_got: list[bytes] = []
    with _member(tls_router, certificates, "fleet") as fleet, \
            _member(tls_router, certificates, "stranger") as stranger, \
            _member(tls_router, certificates, "edge-a") as edge:
        fleet.declare_subscriber(keys.all_states("fast"),
                                 lambda s: fleet_got.append(s.payload.to_bytes()))
        stranger.declare_subscriber(keys.all_states("fast"),
                                    lambda s: stranger_got.append(s.payload.to_bytes()))

        def edge_heard() -> bool:
            edge.put(state_key, b'{"from": "edge-a"}')
            return bool(fleet_got)

        wait_for_blocking("a member's state reaching the fleet server", edge_heard, 20.0, 0.2)
        stranger.put(state_key, b'{"from": "stranger"}')
        last = b'{"from": "edge-a", "last": true}'
        edge.put(state_key, last)
        # the edge's later put arrives; the stranger's (sent before it) never does
        wait_for_blocking("the edge's next state", lambda: last in fleet_got, 20.0)
        time.sleep(0.3)
        assert b'{"from": "stranger"}' not in fleet_got
        # what the stranger hears is only what it put itself (a session delivers its own
        # puts locally): nothing of the fleet's
        holds_for_blocking("the stranger hearing none of the edge's states",
                           lambda: b'{"from": "edge-a"}' not in stranger_got, 1.0)
