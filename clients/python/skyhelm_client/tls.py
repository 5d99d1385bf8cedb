"""The TLS context every client of this process shares.

httpx builds a context for each client it opens, whether or not the server speaks TLS, and
reading the CA bundle takes ~40 ms of CPU: a script that opens a client per vehicle or per
step paid it each time. Built on first use with httpx's defaults (the certifi bundle, or
``SSL_CERT_FILE``/``SSL_CERT_DIR`` as set then) and kept, a client opens in a tenth of a
millisecond."""

from __future__ import annotations

import functools
import ssl

import httpx

__all__ = ["default_tls"]


@functools.cache
def default_tls() -> ssl.SSLContext:
    """httpx's default context, built once per process."""
    return httpx.create_ssl_context()
