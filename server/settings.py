"""Server settings: CLI flags > SKYHELM_* environment > TOML file (--config) > defaults."""

from __future__ import annotations

import hmac
import logging
import os
import secrets
from contextvars import ContextVar
from pathlib import Path
from typing import Annotated, Any, Literal
from urllib.parse import urlsplit

from pydantic import (
    Field,
    SecretStr,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_settings import (
    BaseSettings,
    NoDecode,
    PydanticBaseSettingsSource,
    SettingsConfigDict,
    TomlConfigSettingsSource,
)

from server.link.codec.urls import LinkUrlError, parse_link_url
from server.link.stream.streamer import DEFAULT_RATE_HZ, MAX_RATE_HZ, MIN_RATE_HZ
from skyhelm_wire.fleet import FLEET_NAME_PATTERN

OperatorLossAction = Literal["hold", "land", "rtl", "hold-mode", "continue"]
Airframe = Literal["quad", "hexa", "octo", "plane", "vtol", "rover"]

log = logging.getLogger(__name__)

# The TOML path is only known at load time; pydantic-settings builds sources per class.
_CONFIG_FILE: ContextVar[Path | None] = ContextVar("skyhelm_config_file", default=None)


# The 2D map's tiles: one URL template, also the one host the page's CSP lets images come
# from (tile_origin).
_PLACEHOLDERS = ("{z}", "{x}", "{y}")


def check_tile_url(url: str) -> str:
    """A Leaflet tile template: http(s), a host, and the {z}/{x}/{y} placeholders."""
    parts = urlsplit(url.replace("{s}", "a"))
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise ValueError("map_tile_url must be an http(s) URL with a host")
    missing = [p for p in _PLACEHOLDERS if p not in url]
    if missing:
        raise ValueError(f"map_tile_url lacks {', '.join(missing)}")
    return url


def tile_origin(url: str | None) -> str | None:
    """The origin tiles come from, for the CSP's img-src ("https://*.tile.example.org" when
    the template spreads over {s} subdomains); None without tiles."""
    if url is None:
        return None
    parts = urlsplit(url.replace("{s}", "a"))
    host = parts.netloc
    if "{s}" in url:
        host = "*." + host.split(".", 1)[1] if "." in host else host
    return f"{parts.scheme}://{host}"



def _default_web_dir() -> Path | None:
    candidate = Path(__file__).resolve().parent.parent / "web"
    return candidate if candidate.is_dir() else None


class Settings(BaseSettings):
    # A bound that code below also checks is that code's constant (the streamer's rate), so
    # a value that passes here never fails later at run time; NaN and infinity never pass.
    model_config = SettingsConfigDict(
        env_prefix="SKYHELM_", extra="forbid", frozen=True, allow_inf_nan=False
    )

    host: str = "127.0.0.1"
    port: int = Field(8000, ge=0, le=65535)
    token: SecretStr | None = Field(None, description="pilot token; generated when unset")
    token_file: Path | None = Field(
        None,
        description="where `skyhelm serve` keeps the token it generated (0600), so its URL "
        "survives a restart; default $XDG_STATE_HOME/skyhelm/token",
    )
    observer_token: SecretStr | None = None
    connect: Annotated[list[str], NoDecode] = Field(
        default_factory=list, description="MAVLink URLs of real vehicles; none = start the sim"
    )
    sim_airframe: Airframe = "quad"
    sim_count: int = Field(1, ge=1, le=100)
    sim_speed: float = Field(1.0, gt=0.0, le=50.0)
    rate_hz: float = Field(
        DEFAULT_RATE_HZ, ge=MIN_RATE_HZ, le=MAX_RATE_HZ, description="offboard setpoint rate"
    )
    lease_ttl_s: float = Field(
        120.0, ge=0.2, le=86400.0, description="control lease TTL when the client asks none"
    )
    lease_ttl_min_s: float = Field(1.0, ge=0.2, le=86400.0)
    lease_ttl_max_s: float = Field(600.0, ge=0.2, le=86400.0)
    deadman_timeout_s: float = Field(
        1.0, ge=0.2, le=10.0, description="live setpoints: brake and hold after this silence"
    )
    takeover_ask_s: float = Field(10.0, ge=0.5, le=120.0, description="holder's time to answer")
    token_name: str = Field("pilot", min_length=1, max_length=32)
    observer_token_name: str = Field("observer", min_length=1, max_length=32)
    on_operator_loss: OperatorLossAction = "hold"
    max_alt_rel_m: float | None = Field(120.0, gt=0.0)
    max_distance_m: float | None = Field(500.0, gt=0.0)
    max_speed_xy_m_s: float | None = Field(12.0, gt=0.0)
    max_speed_z_m_s: float | None = Field(5.0, gt=0.0)
    log_dir: Path | None = Path("logs")
    signing_key_file: Path | None = Field(
        None, description="MAVLink 2 signing key (64 hex digits); POST /api/v1/signing writes "
        "it; the embedded sim keeps its keys beside it"
    )
    cors_origins: Annotated[list[str], NoDecode] = Field(default_factory=list)
    telemetry_max_rate_hz: float = Field(50.0, gt=0.0, le=200.0)
    heartbeat_timeout_s: float = Field(
        5.0, ge=5.0, le=60.0,
        description="a vehicle sending little besides its HEARTBEAT is lost after this long "
        "without a frame (the MAVLink heartbeat protocol's 5 s at least)",
    )
    silence_timeout_s: float = Field(
        1.0, ge=0.2, le=60.0,
        description="a vehicle streaming telemetry is lost after this long without a frame",
    )
    vehicle_wait_s: float = Field(
        20.0, ge=0.0, description="how long startup waits for each simulated vehicle"
    )
    scene: bool = True
    # Foxglove (docs/foxglove.md). The SDK's server checks no token, so it listens on
    # 127.0.0.1 only; /api/v1/foxglove is the way in with a token.
    foxglove_port: int | None = Field(
        None, ge=0, le=65535,
        description="Foxglove WebSocket server on 127.0.0.1 (0 picks a free port); none = off",
    )
    mcap: bool = Field(False, description="record an MCAP file beside each .tlog")
    map_tile_url: str | None = Field(
        None,
        description="2D map tiles, e.g. https://tile.openstreetmap.org/{z}/{x}/{y}.png; "
        "none = an offline metre grid",
    )
    map_tile_attribution: str = Field("", max_length=200, description="shown on the map")
    map_tiles: Path | None = Field(
        None,
        description="offline 2D map tiles: a PMTiles or MBTiles archive of raster tiles, "
        "served at /api/v1/tiles/{z}/{x}/{y}.{png|jpg|webp} (skyhelm tiles makes one)",
    )
    web_dir: Path | None = Field(default_factory=_default_web_dir)
    # Abuse limits (docs/api.md, "Security"): per token, per client address.
    control_rate_per_s: float = Field(
        100.0, gt=0.0, le=100000.0, description="REST control calls per second, per token"
    )
    control_burst: int = Field(200, ge=1, le=100000, description="REST control calls at once")
    ws_message_rate_per_s: float = Field(
        100.0, gt=0.0, le=100000.0, description="control-socket messages per second, per token"
    )
    ws_message_burst: int = Field(200, ge=1, le=100000, description="control-socket burst")
    ws_abuse_close_after: int = Field(
        200, ge=1, le=1000000, description="refused control messages in a row before closing"
    )
    lockout_free_failures: int = Field(
        10, ge=1, le=10000, description="wrong tokens per address before backing off"
    )
    lockout_base_s: float = Field(1.0, gt=0.0, le=3600.0, description="first lockout")
    lockout_max_s: float = Field(300.0, gt=0.0, le=86400.0, description="longest lockout")
    access_log: bool = True
    tls_cert: Path | None = Field(None, description="PEM certificate: serve https and wss")
    tls_key: Path | None = Field(None, description="PEM private key of tls_cert")
    # The fleet over Zenoh (docs/fleet.md): an edge publishes its vehicles and answers
    # commands (zenoh); a fleet server sees and flies every edge's vehicles (fleet).
    zenoh: bool = Field(False, description="publish this server's vehicles to the fleet")
    fleet: bool = Field(False, description="see and fly every edge of the fleet")
    fleet_name: str = Field(
        "default", pattern=FLEET_NAME_PATTERN, description="the fleet (a Zenoh key chunk)"
    )
    edge_name: str | None = Field(
        None, pattern=FLEET_NAME_PATTERN,
        description="this edge's name in the fleet (default: the host name)",
    )
    zenoh_mode: Literal["peer", "client"] = "peer"
    zenoh_connect: Annotated[list[str], NoDecode] = Field(
        default_factory=list, description="Zenoh endpoints to connect to, e.g. a router's"
    )
    zenoh_listen: Annotated[list[str], NoDecode] = Field(default_factory=list)
    zenoh_multicast_scouting: bool = True
    zenoh_config: Path | None = Field(
        None, description="Zenoh JSON5 configuration (TLS, access control)"
    )

    @field_validator("connect", "cors_origins", "zenoh_connect", "zenoh_listen", mode="before")
    @classmethod
    def _split_commas(cls, value: Any) -> Any:
        if isinstance(value, str):
            return [item.strip() for item in value.split(",") if item.strip()]
        return value

    @field_validator("connect")
    @classmethod
    def _check_urls(cls, urls: list[str]) -> list[str]:
        for url in urls:
            try:
                parse_link_url(url)
            except LinkUrlError as exc:
                raise ValueError(str(exc)) from None
        return urls

    @field_validator("map_tile_url")
    @classmethod
    def _check_tile_url(cls, url: str | None) -> str | None:
        if url is None or not url.strip():
            return None
        return check_tile_url(url.strip())

    @field_validator("token", "observer_token")
    @classmethod
    def _check_token(cls, token: SecretStr | None) -> SecretStr | None:
        if token is not None and len(token.get_secret_value()) < 8:
            raise ValueError("tokens must be at least 8 characters")
        return token

    @field_validator("lease_ttl_max_s")
    @classmethod
    def _lease_ttl_in_bounds(cls, max_s: float, info: ValidationInfo) -> float:
        # checked on the last of the three fields, so the message shows no other setting
        default_s, min_s = info.data.get("lease_ttl_s"), info.data.get("lease_ttl_min_s")
        if default_s is not None and min_s is not None and not min_s <= default_s <= max_s:
            raise ValueError(
                f"lease_ttl_s ({default_s}) must lie within lease_ttl_min_s ({min_s}) "
                f"and lease_ttl_max_s ({max_s})"
            )
        return max_s

    @model_validator(mode="after")
    def _tokens_differ(self) -> Settings:
        if (
            self.token is not None
            and self.observer_token is not None
            and hmac.compare_digest(
                self.token.get_secret_value().encode(),
                self.observer_token.get_secret_value().encode(),
            )
        ):
            raise ValueError("observer_token must differ from token")
        return self

    @model_validator(mode="after")
    def _one_tile_source(self) -> Settings:
        if self.map_tiles is not None and self.map_tile_url is not None:
            raise ValueError("map_tiles and map_tile_url both name the map's tiles: give one")
        return self

    @model_validator(mode="after")
    def _tls_pair(self) -> Settings:
        if (self.tls_cert is None) != (self.tls_key is None):
            raise ValueError("tls_cert and tls_key go together: give both or neither")
        for path in (self.tls_cert, self.tls_key):
            if path is not None and not path.is_file():
                raise ValueError(f"no TLS file at {path}")
        return self

    @property
    def tls(self) -> bool:
        return self.tls_cert is not None

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        sources: list[PydanticBaseSettingsSource] = [init_settings, env_settings]
        config_file = _CONFIG_FILE.get()
        if config_file is not None:
            sources.append(TomlConfigSettingsSource(settings_cls, toml_file=config_file))
        return tuple(sources)

    def pilot_token(self) -> str:
        assert self.token is not None, "load_settings() always fills the token"
        return self.token.get_secret_value()


_SECRET_FIELDS = frozenset({"token", "observer_token"})


class SettingsError(ValueError):
    """A setting has a bad value; the message names the setting and the reason."""


def default_token_file() -> Path:
    """$XDG_STATE_HOME/skyhelm/token (~/.local/state/skyhelm/token): state the server makes
    and keeps, as the XDG base directory specification places it."""
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "skyhelm" / "token"


def kept_token(path: Path) -> str:
    """The token kept in ``path``, or a new one written there readable by its owner only
    (0600, in a 0700 directory). A file others may read is made 0600 first; a token file
    that cannot be read or written leaves a token for this run only, with a warning."""
    try:
        if path.is_file():
            if path.stat().st_mode & 0o077:
                path.chmod(0o600)
                log.warning("token file %s was readable by others: made 0600", path)
            kept = path.read_text().strip()
            if len(kept) >= 8:
                return kept
            log.warning("token file %s holds no token: writing a new one", path)
        path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        token = secrets.token_urlsafe(24)
        # written whole under another name, then renamed: a second server starting at the
        # same moment reads a whole token, never half of one
        partial = path.with_name(f".{path.name}.{os.getpid()}")
        fd = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as out:
            out.write(token + "\n")
        partial.replace(path)
        return token
    except OSError as exc:
        log.warning("cannot keep the token in %s (%s): it changes at the next start", path, exc)
        return secrets.token_urlsafe(24)


def load_settings(
    config_file: Path | None = None, *, keep_token: bool = False, **overrides: Any
) -> Settings:
    """Build settings from overrides (CLI flags), SKYHELM_* env, then the TOML file. Without
    a token one is generated: with ``keep_token`` (``skyhelm serve``) the one kept in the
    token file, so the printed URL stays the same from one start to the next."""
    if config_file is not None and not config_file.is_file():
        raise SettingsError(f"config file {config_file} does not exist")
    reset = _CONFIG_FILE.set(config_file)
    try:
        settings = Settings(**overrides)
    except ValidationError as exc:
        raise SettingsError(_describe(exc)) from None
    except ValueError as exc:  # malformed TOML
        raise SettingsError(f"cannot read {config_file}: {exc}") from None
    finally:
        _CONFIG_FILE.reset(reset)
    if settings.token is None:
        token = (
            kept_token(settings.token_file or default_token_file())
            if keep_token
            else secrets.token_urlsafe(24)
        )
        settings = settings.model_copy(update={"token": SecretStr(token)})
    return settings


def _describe(exc: ValidationError) -> str:
    lines = []
    for error in exc.errors():
        field = ".".join(str(part) for part in error["loc"]) or "settings"
        if error["type"] == "extra_forbidden":
            lines.append(f"{field}: unknown setting")
        # never echoed: a secret's value, or a whole-model error's input (every setting,
        # tokens included)
        elif field in _SECRET_FIELDS or not error["loc"]:
            lines.append(f"{field}: {error['msg']}")
        else:
            lines.append(f"{field}: {error['msg']} (got {error.get('input')!r})")
    return "invalid settings: " + "; ".join(lines)
