"""TLS served directly: `--tls-cert/--tls-key` make `skyhelm serve`'s uvicorn speak https and
wss (a trustme certificate for 127.0.0.1 here); the printed URL says https; a half pair or a
missing file stops startup with a message naming the setting."""

from __future__ import annotations

import asyncio
import json
import ssl
from collections.abc import AsyncIterator
from pathlib import Path

import httpx
import pytest
import trustme
from websockets.asyncio.client import connect

from server.cli import main, ready_url
from server.settings import SettingsError, load_settings
from tests.api.conftest import PILOT, auth
from tests.api.uvicorn_run import uvicorn_serving


@pytest.fixture(scope="module")
def ca() -> trustme.CA:
    return trustme.CA()


@pytest.fixture
def cert_files(ca: trustme.CA, tmp_path: Path) -> tuple[Path, Path]:
    leaf = ca.issue_cert("127.0.0.1", "localhost")
    cert, key = tmp_path / "cert.pem", tmp_path / "key.pem"
    leaf.private_key_pem.write_to_path(str(key))
    leaf.cert_chain_pems[0].write_to_path(str(cert))
    return cert, key


@pytest.fixture
async def https_server(cert_files: tuple[Path, Path]) -> AsyncIterator[int]:
    cert, key = cert_files
    settings = load_settings(
        port=0, token=PILOT, connect=["udpin:127.0.0.1:0"], scene=False, log_dir=None,
        tls_cert=cert, tls_key=key, access_log=False,
    )
    async with uvicorn_serving(settings) as port:
        assert ready_url(settings, port) == f"https://127.0.0.1:{port}/?token={PILOT}"
        yield port


async def test_https_and_wss_with_a_trusted_certificate(
    https_server: int, ca: trustme.CA
) -> None:
    trusted = ssl.create_default_context()
    ca.configure_trust(trusted)
    base = f"https://127.0.0.1:{https_server}"
    async with httpx.AsyncClient(base_url=base, verify=trusted) as client:
        response = await client.get("/api/v1/vehicles", headers=auth())
        assert response.status_code == 200
        assert response.json() == []
        session = await client.post("/api/v1/session", headers=auth())
        assert "Secure" in session.headers["set-cookie"]
    url = f"wss://127.0.0.1:{https_server}/api/v1/ws/telemetry?token={PILOT}"
    async with connect(url, ssl=trusted) as ws:
        assert json.loads(await asyncio.wait_for(ws.recv(), 10.0))["type"] == "vehicles"
    # a client that does not trust the CA is refused by TLS itself
    async with httpx.AsyncClient(base_url=base) as untrusting:
        with pytest.raises(httpx.ConnectError):
            await untrusting.get("/api/v1/health")
    # plain http to the TLS port gets no API answer
    async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{https_server}") as plain:
        with pytest.raises(httpx.HTTPError):
            (await plain.get("/api/v1/health")).raise_for_status()


def test_tls_settings_come_in_pairs_of_existing_files(
    cert_files: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cert, key = cert_files
    with pytest.raises(SettingsError, match="tls_cert and tls_key go together"):
        load_settings(tls_cert=cert)
    with pytest.raises(SettingsError, match="no TLS file at"):
        load_settings(tls_cert=cert, tls_key=tmp_path / "missing.pem")
    assert main(["serve", "--tls-key", str(key), "--port", "0"]) == 2
    assert "tls_cert and tls_key go together" in capsys.readouterr().err
