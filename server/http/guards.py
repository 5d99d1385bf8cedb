"""The server's abuse limits as every surface applies them (the security middleware, the
control socket, the fleet edge): rate limits per token, the wrong-token lockout per
address, and how a refusal reads. No web framework here."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

from server.control.auth import Role, TokenChecker
from server.control.auth_lockout import Lockout
from server.control.ratelimit import RateLimiter
from server.settings import Settings

SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})


@dataclass
class Guards:
    """The server's abuse limits: REST control calls and control-socket messages per token,
    wrong tokens per address."""

    control: RateLimiter
    ws_messages: RateLimiter
    lockout: Lockout
    ws_close_after: int

    @classmethod
    def from_settings(cls, settings: Settings) -> Guards:
        return cls(
            control=RateLimiter(settings.control_rate_per_s, settings.control_burst),
            ws_messages=RateLimiter(settings.ws_message_rate_per_s, settings.ws_message_burst),
            lockout=Lockout(
                settings.lockout_free_failures, settings.lockout_base_s, settings.lockout_max_s
            ),
            ws_close_after=settings.ws_abuse_close_after,
        )

    def admit_token(
        self, tokens: TokenChecker, address: str, token: str
    ) -> tuple[Role | None, Refusal | None]:
        """The token's role (None: wrong), or a refusal while the address is locked out;
        a wrong token counts against the address, a right one clears it."""
        wait_s = self.lockout.retry_after_s(address)
        if wait_s > 0:
            return None, Refusal(LOCKED_OUT_REASON, wait_s)
        role = tokens.role_of(token)
        if role is None:
            self.lockout.failed(address)
        else:
            self.lockout.succeeded(address)
        return role, None

    def admit_call(self, role: Role, method: str) -> Refusal | None:
        """A refusal when a control call (any method but GET/HEAD/OPTIONS) goes over the
        token's rate limit."""
        if method in SAFE_METHODS:
            return None
        wait_s = self.control.take(role.value)
        if wait_s <= 0:
            return None
        reason = (
            f"rate limit: {self.control.rate_per_s:g} control calls/s "
            f"(burst {self.control.burst:g}) per token"
        )
        return Refusal(reason, wait_s)


LOCKED_OUT_REASON = "too many wrong tokens from this address; try again later"


@dataclass(frozen=True)
class Refusal:
    """A call refused before it runs: 429, with the wait for Retry-After."""

    reason: str
    retry_after_s: float
    status: int = 429


def retry_after_header(wait_s: float) -> str:
    """Retry-After is whole seconds; never 0 for a refusal."""
    return str(max(1, math.ceil(wait_s)))


def refusal_body(reason: str, retry_after_s: float | None, **cause: str) -> bytes:
    detail: dict[str, Any] = {"reason": reason, **cause}
    if retry_after_s is not None:
        detail["retry_after_s"] = round(retry_after_s, 3)
    return json.dumps({"detail": detail}).encode()
