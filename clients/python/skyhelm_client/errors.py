"""What a refused call raises: one exception type per HTTP status the API answers with, each
carrying the status, the reason, and whatever else the answer names (the MAV_RESULT of a
refused command, the field and limit of bad input, the lease holder)."""

from __future__ import annotations

from typing import Any

from skyhelm_wire.commands import CommandResultOut
from skyhelm_wire.common import ErrorDetail


class SkyHelmError(Exception):
    """A call the server refused or could not carry out: the HTTP status (0 when the server
    could not be reached), the server's reason, and what else the answer named."""

    def __init__(self, status: int, reason: str, *, body: Any = None, **named: Any) -> None:
        super().__init__(f"{status}: {reason}" if status else reason)
        self.status = status
        self.reason = reason
        self.body = body  # the answer as received
        # a command the vehicle answered: its outcome (DENIED, ...) and MAV_RESULT
        self.result: str | None = named.get("result")
        self.result_code: int | None = named.get("result_code")
        # bad input: the field, and the limit it broke
        self.field: str | None = named.get("field")
        self.limit: float | None = named.get("limit")
        # who holds the control lease
        self.holder: str | None = named.get("holder")


class Unauthorized(SkyHelmError):
    """401: no token, or a wrong one."""


class Forbidden(SkyHelmError):
    """403: an observer token on a control call, or a read-only replay."""


class NotFound(SkyHelmError):
    """404: no such vehicle (or request)."""


class Refused(SkyHelmError):
    """409: the vehicle refused (``result``, ``result_code``, its ``reason``), another pilot
    holds the lease (``holder``), or a takeover was denied or not answered."""


class InvalidInput(SkyHelmError):
    """422: a body the server will not take; ``field`` names it, ``limit`` the bound broken."""


class NoLease(SkyHelmError):
    """423: a control call without the lease, or with one that lapsed or was taken over."""


class Unavailable(SkyHelmError):
    """503: the vehicle is not connected or its link was lost."""


class NoAnswer(SkyHelmError):
    """504: the vehicle did not answer (a command's retries ran out), or a wait timed out."""


_BY_STATUS: dict[int, type[SkyHelmError]] = {
    401: Unauthorized,
    403: Forbidden,
    404: NotFound,
    409: Refused,
    422: InvalidInput,
    423: NoLease,
    503: Unavailable,
    504: NoAnswer,
}


def error_for(status: int, body: Any) -> SkyHelmError:
    """The exception for an answer that is not a success: a command result (409/503/504
    with ``result``), ``{"detail": {reason, field, limit, holder}}``, or pydantic's list of
    field errors."""
    cls = _BY_STATUS.get(status, SkyHelmError)
    if isinstance(body, dict) and "result" in body:
        command = CommandResultOut.model_validate(body)
        return cls(
            status,
            command.reason or command.result,
            result=command.result,
            result_code=command.result_code,
            body=body,
        )
    detail = body.get("detail") if isinstance(body, dict) else None
    if isinstance(detail, dict) and "reason" in detail:
        error = ErrorDetail.model_validate(detail)
        return cls(
            status,
            error.reason,
            field=error.field,
            limit=error.limit,
            holder=error.holder,
            body=body,
        )
    if isinstance(detail, list) and detail and isinstance(detail[0], dict):
        # pydantic's errors: the first one's location, without the leading "body"
        location = [str(part) for part in detail[0].get("loc", ()) if part != "body"]
        reasons = "; ".join(str(error.get("msg", error)) for error in detail)
        return cls(status, reasons, field=".".join(location) or None, body=body)
    return cls(status, str(detail if detail is not None else body), body=body)


class WaitTimedOut(SkyHelmError, TimeoutError):
    """``wait_until`` ran out of time; ``body`` is the last state seen."""


def timed_out(what: str, last: Any) -> WaitTimedOut:
    return WaitTimedOut(0, f"timed out waiting for {what}; the vehicle last showed {last!r}",
                        body=last)  # fmt: skip
