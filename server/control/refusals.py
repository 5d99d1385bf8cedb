"""What the control core refuses, said without a transport: each adapter (REST, the control
socket, the fleet edge) answers it its own way (server/http/errors.py: as HTTP)."""

from __future__ import annotations


class InvalidInput(ValueError):
    """An input the call cannot take: its reason, the input it names (``field``) and what
    else tells the caller why (``cause``: e.g. the range it broke; None values left out)."""

    def __init__(
        self, reason: str, *, field: str | None = None, **cause: str | float | None
    ) -> None:
        super().__init__(reason)
        self.reason = reason
        self.field = field
        self.cause = {key: value for key, value in cause.items() if value is not None}
