"""What the control core refuses, said without a transport: each adapter (REST, the control
socket, the fleet edge) answers it its own way (server/http/errors.py: as HTTP)."""

from __future__ import annotations


class InvalidInput(ValueError):
    """An input the call cannot take: its reason and the input it names (``field``)."""

    def __init__(self, reason: str, *, field: str | None = None) -> None:
        super().__init__(reason)
        self.reason = reason
        self.field = field
