"""Tokens and roles. A pilot token may do everything, an observer token only reads; tokens are
compared in constant time and never logged."""

from __future__ import annotations

import enum
import hmac
from collections.abc import Mapping

TOKEN_COOKIE = "skyhelm_token"
TOKEN_QUERY = "token"


class Role(enum.Enum):
    PILOT = "pilot"
    OBSERVER = "observer"


class TokenChecker:
    def __init__(self, pilot_token: str, observer_token: str | None = None) -> None:
        self._pilot = pilot_token.encode()
        self._observer = observer_token.encode() if observer_token else None

    def role_of(self, token: str | None) -> Role | None:
        if not token:
            return None
        candidate = token.encode()
        # Both comparisons always run so timing does not tell which token was close.
        is_pilot = hmac.compare_digest(candidate, self._pilot)
        is_observer = self._observer is not None and hmac.compare_digest(candidate, self._observer)
        if is_pilot:
            return Role.PILOT
        if is_observer:
            return Role.OBSERVER
        return None

    def is_valid(self, token: str | None) -> bool:
        return self.role_of(token) is not None


def token_from(
    headers: Mapping[str, str], query: Mapping[str, str], cookies: Mapping[str, str]
) -> str | None:
    """The token a request carries: Bearer header first, then ?token=, then the cookie."""
    authorization = headers.get("authorization", "")
    scheme, _, credentials = authorization.partition(" ")
    if scheme.lower() == "bearer" and credentials.strip():
        return credentials.strip()
    return query.get(TOKEN_QUERY) or cookies.get(TOKEN_COOKIE) or None
