"""The control lease: the request to take it and what the API says about it."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, Field

from server.api.schemas.common import StrictBody


class ControlBody(StrictBody):
    takeover: bool = False
    client_name: Annotated[str | None, Field(max_length=64, description="shown to others")] = None


class LeaseOut(BaseModel):
    lease_id: str
    ttl_s: float
    holder: str
    expires_in_s: float


class LeaseStatusOut(BaseModel):
    holder: str | None
    expires_in_s: float | None
