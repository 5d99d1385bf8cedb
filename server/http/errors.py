"""How failures become HTTP answers: the status and body of each refusal the link and the
control core raise (transport-neutral), as REST, the control socket and the fleet edge
answer them. Bad input is a 422 naming the field, a vehicle's refusal a 409 carrying its
MAV_RESULT and reason, no answer a 504, a lost vehicle a 503: never a 500. No web framework
here (the fleet edge answers through it): the app installs it with ``error_handlers``."""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from typing import Any

from pydantic import BaseModel, ValidationError

from server.control.lease import (
    LeaseHeld,
    LeaseInvalid,
    TakeoverRefused,
    TtlOutOfBounds,
    UnknownRequest,
)
from server.control.lease_ops import AskerGone
from server.control.operations import command_out
from server.control.refusals import InvalidInput
from server.http.schemas import CommandResultOut, ErrorOut, UnprocessableOut
from server.link import CommandOutcome, CommandResult, ParamError, ParamUnknown, SetpointRejected


class ApiError(Exception):
    """A failure the client can act on: the status, a reason, and what names the cause
    (``field`` the offending input, ``limit`` the bound it broke, ``holder`` who holds the
    lease); keys given as None are left out of ``detail``."""

    def __init__(
        self,
        status_code: int,
        reason: str,
        *,
        headers: dict[str, str] | None = None,
        **cause: str | float | None,
    ) -> None:
        super().__init__(reason)
        self.status_code = status_code
        self.detail: dict[str, Any] = {"reason": reason}
        self.detail.update((key, value) for key, value in cause.items() if value is not None)
        self.headers = headers


# A command's outcome decides the status; the body is always the full CommandResultOut.
COMMAND_STATUS: dict[CommandOutcome, int] = {
    CommandOutcome.ACCEPTED: 200,
    CommandOutcome.IN_PROGRESS: 202,
    CommandOutcome.TEMPORARILY_REJECTED: 409,
    CommandOutcome.DENIED: 409,
    CommandOutcome.UNSUPPORTED: 409,
    CommandOutcome.FAILED: 409,
    CommandOutcome.CANCELLED: 409,
    CommandOutcome.NOT_CONFIRMED: 409,
    CommandOutcome.TIMEOUT: 504,
    CommandOutcome.LINK_LOST: 503,
}


def command_status(outcome: CommandOutcome | None) -> int:
    """A command's status by its outcome; 200 for what sent no command (a setpoint)."""
    return 200 if outcome is None else COMMAND_STATUS[outcome]


def command_answer(result: CommandResult) -> tuple[int, dict[str, Any]]:
    """A command's status and JSON body."""
    return COMMAND_STATUS[result.outcome], command_out(result).model_dump(mode="json")


def _described(model: type[BaseModel], description: str) -> dict[str, Any]:
    return {"model": model, "description": description}


Responses = dict[int | str, dict[str, Any]]
AUTH_RESPONSES: Responses = {
    401: _described(ErrorOut, "missing or wrong token"),
    429: _described(ErrorOut, "rate limit, or too many wrong tokens: see Retry-After"),
    422: _described(UnprocessableOut, "invalid request: the field and the reason"),
}
READ_RESPONSES: dict[int | str, dict[str, Any]] = {
    **AUTH_RESPONSES,
    404: _described(ErrorOut, "no such vehicle"),
}
CONTROL_RESPONSES: dict[int | str, dict[str, Any]] = {
    **READ_RESPONSES,
    403: _described(ErrorOut, "observer tokens may only read; a replay is read-only"),
    423: _described(ErrorOut, "the call needs the vehicle's control lease (X-Lease-Id)"),
    503: _described(ErrorOut, "the vehicle is not connected"),
}
COMMAND_RESPONSES: dict[int | str, dict[str, Any]] = {
    **CONTROL_RESPONSES,
    202: _described(CommandResultOut, "the vehicle reported the command still in progress"),
    # not connected before the call (ErrorOut), or the link lost during it (LINK_LOST)
    503: {"model": ErrorOut | CommandResultOut, "description": "the vehicle is not connected"},
    409: _described(CommandResultOut, "the vehicle refused: MAV_RESULT and its reason"),
    504: _described(CommandResultOut, "no answer from the vehicle"),
}


def error_status(exc: Exception) -> tuple[int, dict[str, Any]] | None:
    """The HTTP status and `detail` for a failure the API expects; None for a real bug.
    REST handlers and the WebSocket control session both answer through this."""
    if isinstance(exc, ApiError):
        return exc.status_code, exc.detail
    if isinstance(exc, InvalidInput):
        return 422, {"reason": exc.reason, **({"field": exc.field} if exc.field else {}),
                     **exc.cause}
    if isinstance(exc, LeaseHeld):
        return 409, {"reason": str(exc), "holder": exc.lease.holder}
    if isinstance(exc, TakeoverRefused):
        return 409, {"reason": str(exc), "holder": exc.holder}
    if isinstance(exc, TtlOutOfBounds):
        return 422, {"reason": str(exc), "field": "ttl_s", "limit": exc.limit}
    if isinstance(exc, UnknownRequest):
        return 404, {"reason": str(exc)}
    if isinstance(exc, AskerGone):
        # nobody reads this answer; 499 is what proxies log for a client that left
        return 499, {"reason": "the client asking for control went away"}
    if isinstance(exc, SetpointRejected):
        return 422, {"reason": exc.reason, "field": exc.field, "limit": exc.limit}
    if isinstance(exc, ValidationError):
        return 422, {"reason": _validation_reason(exc), "field": _validation_field(exc)}
    if isinstance(exc, LeaseInvalid):
        locked: dict[str, Any] = {"reason": str(exc)}
        if exc.holder is not None:  # who holds control now, e.g. after a takeover
            locked["holder"] = exc.holder
        return 423, locked
    if isinstance(exc, ParamUnknown):
        return 404, {"reason": str(exc)}
    if isinstance(exc, ParamError):
        return 409, {"reason": str(exc)}
    if isinstance(exc, TimeoutError):
        return 504, {"reason": str(exc) or "no answer from the vehicle"}
    return None


def _validation_field(exc: ValidationError) -> str | None:
    errors = exc.errors()
    return ".".join(str(part) for part in errors[0]["loc"]) or None if errors else None


def _validation_reason(exc: ValidationError) -> str:
    return "; ".join(
        f"{'.'.join(str(p) for p in error['loc']) or 'body'}: {error['msg']}"
        for error in exc.errors()
    )


def json_safe(value: Any) -> Any:
    """``value`` with every NaN or infinity as a string ("nan", "inf", "-inf"): JSON has no
    such numbers, and an error answer must be able to echo the input that caused it."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {key: json_safe(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(item) for item in value]
    return value


def non_finite_field(value: Any, path: str = "") -> str | None:
    """The dotted name of the first NaN or infinity in parsed JSON (``setpoint.north_m``,
    ``id``), or None: a WebSocket message is parsed by json.loads, which takes them."""
    if isinstance(value, float) and not math.isfinite(value):
        return path or "message"
    items: Any = ()
    if isinstance(value, dict):
        items = value.items()
    elif isinstance(value, list):
        items = enumerate(value)
    for key, item in items:
        found = non_finite_field(item, f"{path}.{key}" if path else str(key))
        if found is not None:
            return found
    return None


def refuse_non_finite(message: Any) -> None:
    """422 naming the field when a parsed message holds NaN or infinity."""
    field = non_finite_field(message)
    if field is not None:
        raise ApiError(422, "NaN and infinity are not numbers (JSON has neither)", field=field)


def validation_detail(errors: Sequence[Any]) -> list[Any]:
    """The ``detail`` of a 422 for invalid input: FastAPI's errors, safe to encode (as its
    jsonable_encoder writes them: an exception in ``ctx`` as {}, a tuple as a list)."""
    return [json_safe(_plain(error)) for error in errors]


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(key): _plain(item) for key, item in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [_plain(item) for item in value]
    if isinstance(value, enum.Enum):
        return _plain(value.value)
    if isinstance(value, BaseException):
        return {}
    if value is None or isinstance(value, str | int | float | bool):
        return value
    return str(value)


# the failures answered as error_status says; anything else is a bug (500)
ANSWERED_ERRORS: tuple[type[Exception], ...] = (
    ApiError, InvalidInput, SetpointRejected, LeaseInvalid, ParamError, ParamUnknown,
    TimeoutError, LeaseHeld, TakeoverRefused, TtlOutOfBounds, UnknownRequest, AskerGone,
)  # fmt: skip
