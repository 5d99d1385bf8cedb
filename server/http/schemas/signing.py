"""MAVLink 2 signing as the API shows it: per link, counters only, never the key."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from server.http.schemas.common import StrictBody

SigningAction = Literal["generate", "rotate", "disable"]


class SigningOut(BaseModel):
    """One link's signing (also inside every vehicle state's `link`)."""

    model_config = ConfigDict(extra="ignore")

    enabled: bool = Field(description="the link signs what it sends and checks what it gets")
    vehicles_signed: bool = Field(
        description="every vehicle on the link answered with frames verified by our key "
        "within the last 3 s: the link is signed both ways"
    )
    signed_in: int = Field(description="frames accepted with a good signature")
    unsigned_in: int = Field(description="unsigned frames accepted (allowlist, or signing off)")
    rejected: int = Field(description="frames rejected: the three counters below together")
    rejected_bad_signature: int
    rejected_replay: int
    rejected_unsigned: int
    provisions: int = Field(description="keys set, rotated or removed since the server started")


class LinkSigningOut(BaseModel):
    url: str
    vehicles: list[int]
    signing: SigningOut


class SigningStatusOut(BaseModel):
    enabled: bool = Field(description="the server holds a signing key")
    key_file_set: bool = Field(description="signing_key_file is configured: keys can be set")
    links: list[LinkSigningOut]


class SigningBody(StrictBody):
    action: SigningAction = Field(
        description="generate: a first key; rotate: replace the key; disable: remove it. "
        "The server makes the key itself and never shows it."
    )
