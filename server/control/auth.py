"""Tokens and roles. A pilot token may do everything, an observer token only reads; tokens are
compared in constant time and never logged. Each token has a name (settings `token_name`,
`observer_token_name`) that session names start with."""

from __future__ import annotations

import enum
import hmac
from collections.abc import Mapping

from server.settings import Settings

TOKEN_COOKIE = "skyhelm_token"
TOKEN_QUERY = "token"


def same_secret(given: str, expected: str) -> bool:
    """Compare a secret (token, lease id) in constant time; any string may be given."""
    return hmac.compare_digest(_bytes(given), _bytes(expected))


def _bytes(text: str) -> bytes:
    return text.encode("utf-8", "surrogatepass")


class Role(enum.Enum):
    PILOT = "pilot"
    OBSERVER = "observer"


class TokenChecker:
    def __init__(
        self,
        pilot_token: str,
        observer_token: str | None = None,
        *,
        pilot_name: str = Role.PILOT.value,
        observer_name: str = Role.OBSERVER.value,
    ) -> None:
        self._pilot = _bytes(pilot_token)
        self._observer = _bytes(observer_token) if observer_token else None
        # shown in holder names ("pilot · Chrome tab 7f3a"); never the token itself
        self._names = {Role.PILOT: pilot_name, Role.OBSERVER: observer_name}

    @classmethod
    def from_settings(cls, settings: Settings) -> TokenChecker:
        observer = settings.observer_token
        return cls(
            settings.pilot_token(),
            observer.get_secret_value() if observer is not None else None,
            pilot_name=settings.token_name,
            observer_name=settings.observer_token_name,
        )

    def name_of(self, role: Role) -> str:
        """The name of the token that gives this role."""
        return self._names[role]

    def role_of(self, token: str | None) -> Role | None:
        if not token:
            return None
        candidate = _bytes(token)
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
