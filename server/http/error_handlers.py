"""The app's handlers of failures: each answered as ``errors.error_status`` says, and
FastAPI's own 422 with its input echoed safely."""

from __future__ import annotations

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse

from server.http.errors import (
    ANSWERED_ERRORS,
    ApiError,
    command_answer,
    error_status,
    validation_detail,
)
from server.link import CommandResult


def command_response(result: CommandResult) -> JSONResponse:
    status, body = command_answer(result)
    return JSONResponse(body, status_code=status)


async def _handle(_: Request, exc: Exception) -> JSONResponse:
    answer = error_status(exc)
    if answer is None:  # pragma: no cover - registered only for the types above
        raise exc
    status_code, detail = answer
    headers = exc.headers if isinstance(exc, ApiError) else None
    return JSONResponse({"detail": detail}, status_code=status_code, headers=headers)


async def _invalid_request(_: Request, exc: Exception) -> JSONResponse:
    """FastAPI's 422, with the offending input echoed safely (Python's JSON parser takes
    NaN and Infinity, which the answer could not encode: a 500 instead of the 422)."""
    assert isinstance(exc, RequestValidationError)
    return JSONResponse({"detail": validation_detail(exc.errors())}, status_code=422)


def install_error_handlers(app: FastAPI) -> None:
    for exc_type in ANSWERED_ERRORS:
        app.add_exception_handler(exc_type, _handle)
    app.add_exception_handler(RequestValidationError, _invalid_request)
