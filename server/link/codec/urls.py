"""Connection strings in pymavlink's spelling, parsed into a typed address.

Accepted forms (the same strings MAVProxy, MAVSDK and pymavlink users already type):

- ``udpin:HOST:PORT``  listen on UDP, reply to whoever sent (``udp:`` is the same)
- ``udpout:HOST:PORT`` send to a fixed UDP address and listen for its answers
- ``tcp:HOST:PORT``    connect to a TCP server, reconnecting when it goes away
- ``tcpin:HOST:PORT``  serve TCP clients, one or several at once
- ``DEVICE:BAUD`` / ``DEVICE,BAUD`` / ``serial:DEVICE:BAUD`` a serial port (``DEVICE`` alone
  uses :data:`DEFAULT_SERIAL_BAUD`)
- ``tlog:PATH`` / ``tlog:PATH?speed=2&loop=1`` replay a recording (read-only, see replay.py)

IPv6 hosts go in brackets (``udpin:[::1]:14540``). Listeners may use port 0 for an
ephemeral port; ``udpin:`` with an empty host listens on every interface like pymavlink.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

LinkKind = Literal["udpin", "udpout", "tcp", "tcpin", "serial", "tlog"]

# pymavlink's mavlink_connection() default.
DEFAULT_SERIAL_BAUD = 115200

_NETWORK_SCHEMES: dict[str, LinkKind] = {
    "udpin": "udpin",
    "udp": "udpin",
    "udpout": "udpout",
    "tcp": "tcp",
    "tcpin": "tcpin",
}
_LISTENERS: frozenset[LinkKind] = frozenset({"udpin", "tcpin"})
_UNSUPPORTED_SCHEMES = ("udpbcast", "mcast", "uds", "unix", "ws", "wss", "wsserver", "csv")
_BOOLEANS = {"1": True, "true": True, "yes": True, "0": False, "false": False, "no": False}
_STANDARD_BAUDS = frozenset(
    {1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 576000,
     921600, 1000000, 1500000, 2000000, 3000000}
)


class LinkUrlError(ValueError):
    """A connection string that cannot be used; the message says what is wrong and the form."""


@dataclass(frozen=True)
class LinkUrl:
    """A parsed connection string; ``kind`` says which of the groups below is set."""

    kind: LinkKind
    url: str  # as the user typed it, for logs and errors
    # udpin, udpout, tcp, tcpin
    host: str | None = None
    port: int | None = None
    # serial
    device: str | None = None
    baud: int | None = None
    # tlog
    path: str | None = None
    replay_speed: float = 1.0
    replay_loop: bool = False

    @property
    def is_listener(self) -> bool:
        return self.kind in _LISTENERS

    @property
    def label(self) -> str:
        """A short name for logs and file names, e.g. ``udpin-127.0.0.1-14540``."""
        if self.kind == "tlog":
            assert self.path is not None
            return f"tlog-{self.path.rsplit('/', 1)[-1].removesuffix('.tlog')}"
        if self.kind == "serial":
            assert self.device is not None
            return f"serial-{self.device.rsplit('/', 1)[-1]}"
        return f"{self.kind}-{self.host}-{self.port}"


def parse_link_url(url: str) -> LinkUrl:
    """Parse a pymavlink-style connection string; raise LinkUrlError with the reason."""
    text = url.strip()
    if not text:
        raise LinkUrlError("empty connection string; expected e.g. udpin:127.0.0.1:14540")
    scheme, sep, rest = text.partition(":")
    scheme_lower = scheme.lower()
    if sep and scheme_lower in _NETWORK_SCHEMES:
        kind = _NETWORK_SCHEMES[scheme_lower]
        host, port = _split_host_port(rest, kind, text)
        return LinkUrl(kind=kind, url=text, host=host, port=port)
    if sep and scheme_lower in _UNSUPPORTED_SCHEMES:
        raise LinkUrlError(
            f"{scheme_lower}: connections are not supported ({text!r}); "
            "use udpin:, udpout:, tcp:, tcpin: or a serial DEVICE:BAUD"
        )
    if sep and scheme_lower == "tlog":
        return _parse_tlog(rest, text)
    if sep and scheme_lower == "serial":
        return _parse_serial(rest, text)
    return _parse_serial(text, text)


def _split_host_port(rest: str, kind: LinkKind, text: str) -> tuple[str, int]:
    form = f"{kind}:HOST:PORT"
    if rest.startswith("["):
        host, bracket, tail = rest[1:].partition("]")
        if not bracket or not tail.startswith(":"):
            raise LinkUrlError(f"{text!r}: an IPv6 host needs the form {kind}:[ADDR]:PORT")
        port_text = tail[1:]
    else:
        host, colon, port_text = rest.rpartition(":")
        if not colon:
            raise LinkUrlError(f"{text!r}: missing port; expected {form}")
        if ":" in host:
            raise LinkUrlError(f"{text!r}: put an IPv6 host in brackets, {kind}:[ADDR]:PORT")
    if not host:
        if kind not in _LISTENERS:
            raise LinkUrlError(f"{text!r}: missing host; expected {form}")
        host = "0.0.0.0"
    port = _parse_int(port_text, "port", text)
    lowest = 0 if kind in _LISTENERS else 1
    if not lowest <= port <= 65535:
        raise LinkUrlError(f"{text!r}: port {port} is outside {lowest}..65535")
    return host, port


def _parse_serial(rest: str, text: str) -> LinkUrl:
    for separator in (",", ":"):
        device, sep, baud_text = rest.rpartition(separator)
        if sep and baud_text.isdigit() and device:
            baud = _parse_int(baud_text, "baud rate", text)
            if baud not in _STANDARD_BAUDS:
                raise LinkUrlError(
                    f"{text!r}: baud rate {baud} is not a standard rate "
                    f"(e.g. 57600, 115200, 921600)"
                )
            return LinkUrl(kind="serial", url=text, device=device, baud=baud)
    if _looks_like_device(rest):
        return LinkUrl(kind="serial", url=text, device=rest, baud=DEFAULT_SERIAL_BAUD)
    raise LinkUrlError(
        f"unrecognised connection string {text!r}; expected udpin:HOST:PORT, udpout:HOST:PORT, "
        "tcp:HOST:PORT, tcpin:HOST:PORT, tlog:PATH or a serial DEVICE:BAUD such as "
        "/dev/ttyACM0:57600"
    )


def _parse_tlog(rest: str, text: str) -> LinkUrl:
    path, _, query = rest.partition("?")
    if not path:
        raise LinkUrlError(f"{text!r}: missing file; expected tlog:PATH[?speed=S&loop=1]")
    speed = 1.0
    loop = False
    for item in filter(None, query.split("&")):
        key, _, value = item.partition("=")
        if key == "speed":
            try:
                speed = float(value)
            except ValueError:
                raise LinkUrlError(f"{text!r}: speed {value!r} is not a number") from None
            if not 0.0 < speed < float("inf"):
                raise LinkUrlError(f"{text!r}: speed must be a positive number")
        elif key == "loop" and value.lower() in _BOOLEANS:
            loop = _BOOLEANS[value.lower()]
        else:
            raise LinkUrlError(f"{text!r}: unknown option {item!r}; expected speed=S or loop=0|1")
    return LinkUrl(kind="tlog", url=text, path=path, replay_speed=speed, replay_loop=loop)


def _looks_like_device(text: str) -> bool:
    return text.startswith("/dev/") or text.upper().startswith("COM") or text.startswith("/")


def _parse_int(text: str, what: str, url: str) -> int:
    try:
        return int(text, 10)
    except ValueError:
        raise LinkUrlError(f"{url!r}: {what} {text!r} is not a number") from None
