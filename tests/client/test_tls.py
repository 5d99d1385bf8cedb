"""Opening a client reads no CA bundle after the first: scripts that open one per vehicle
or per step paid ~40 ms of CPU each time (skyhelm_client/tls.py)."""

from __future__ import annotations

import asyncio
import ssl
from typing import Any

import pytest

from skyhelm_client import AsyncSkyHelm, SkyHelm
from skyhelm_client.tls import default_tls

URL = "http://127.0.0.1:9/?token=t"  # nothing is sent


def test_clients_share_one_tls_context_read_once(monkeypatch: pytest.MonkeyPatch) -> None:
    reads: list[Any] = []
    load = ssl.SSLContext.load_verify_locations

    def counted(self: ssl.SSLContext, *args: Any, **kwargs: Any) -> None:
        reads.append(args or kwargs)
        load(self, *args, **kwargs)

    monkeypatch.setattr(ssl.SSLContext, "load_verify_locations", counted)
    default_tls.cache_clear()
    try:
        for _ in range(5):
            SkyHelm(URL).close()

        async def open_async() -> None:
            for _ in range(5):
                await AsyncSkyHelm(URL).aclose()

        asyncio.run(open_async())
    finally:
        default_tls.cache_clear()
    assert len(reads) == 1, reads


def test_the_shared_context_verifies_servers_as_httpx_does() -> None:
    context = default_tls()
    assert context.verify_mode == ssl.CERT_REQUIRED
    assert context.check_hostname
    assert context.cert_store_stats()["x509_ca"] > 0
