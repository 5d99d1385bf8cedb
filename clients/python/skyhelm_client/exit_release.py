"""A lease ends with the script that took it: the client gives it back however the script
ends. A ``with`` / ``async with`` block releases it on the way out (normally or through an
exception, KeyboardInterrupt from Ctrl-C included); an interpreter that exits with the lease
still held (no ``with``, an exception escaping ``asyncio.run``) releases it from an
``atexit`` hook; SIGTERM, whose default would end the process without either, is turned
into ``SystemExit`` while a lease is held (only where no handler of the script's own is
installed). A process killed outright (SIGKILL) runs nothing: the server notices that its
process is gone (docs/control.md)."""

from __future__ import annotations

import atexit
import contextlib
import signal
import threading
import weakref
from collections.abc import Callable
from types import FrameType
from typing import Any

import httpx

# how long a release at exit may take: the interpreter is on its way out
EXIT_RELEASE_TIMEOUT_S = 2.0
SIGTERM_EXIT_CODE = 128 + signal.SIGTERM

# each client holding a lease, with the request that releases it
_holding: weakref.WeakKeyDictionary[object, Callable[[], dict[str, Any]]] = (
    weakref.WeakKeyDictionary()
)
_installed = False


def holding(client: object, release_request: Callable[[], dict[str, Any]]) -> None:
    """``client`` holds a lease; ``release_request()`` is the request (httpx's arguments)
    that gives it back."""
    _install()
    _holding[client] = release_request


def released(client: object) -> None:
    _holding.pop(client, None)


def _install() -> None:
    global _installed
    if _installed:
        return
    _installed = True
    atexit.register(release_all)
    if (
        threading.current_thread() is threading.main_thread()
        and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    ):
        signal.signal(signal.SIGTERM, _exit_on_sigterm)


def _exit_on_sigterm(_signum: int, _frame: FrameType | None) -> None:
    raise SystemExit(SIGTERM_EXIT_CODE)


def release_all() -> None:
    """Give back every lease still held (the atexit hook)."""
    for client, release_request in list(_holding.items()):
        released(client)
        # a server that is gone too took the lease with it
        with contextlib.suppress(httpx.HTTPError):
            httpx.request(**release_request(), timeout=EXIT_RELEASE_TIMEOUT_S)
