import pytest

from server.link.codec.urls import DEFAULT_SERIAL_BAUD, LinkUrl, LinkUrlError, parse_link_url


@pytest.mark.parametrize(
    ("url", "expected"),
    [
        ("udpin:127.0.0.1:14600", LinkUrl("udpin", "udpin:127.0.0.1:14600", "127.0.0.1", 14600)),
        ("udp:127.0.0.1:14600", LinkUrl("udpin", "udp:127.0.0.1:14600", "127.0.0.1", 14600)),
        ("udpin::14600", LinkUrl("udpin", "udpin::14600", "0.0.0.0", 14600)),
        ("udpin:127.0.0.1:0", LinkUrl("udpin", "udpin:127.0.0.1:0", "127.0.0.1", 0)),
        ("udpout:10.0.0.2:14601", LinkUrl("udpout", "udpout:10.0.0.2:14601", "10.0.0.2", 14601)),
        ("tcp:localhost:5760", LinkUrl("tcp", "tcp:localhost:5760", "localhost", 5760)),
        ("tcpin:0.0.0.0:5761", LinkUrl("tcpin", "tcpin:0.0.0.0:5761", "0.0.0.0", 5761)),
        ("udpin:[::1]:14600", LinkUrl("udpin", "udpin:[::1]:14600", "::1", 14600)),
        ("UDPOUT:host:9", LinkUrl("udpout", "UDPOUT:host:9", "host", 9)),
    ],
)
def test_network_urls_parse_to_kind_host_and_port(url: str, expected: LinkUrl) -> None:
    assert parse_link_url(url) == expected


@pytest.mark.parametrize(
    ("url", "device", "baud"),
    [
        ("/dev/ttyACM0:57600", "/dev/ttyACM0", 57600),
        ("/dev/ttyUSB1,921600", "/dev/ttyUSB1", 921600),
        ("serial:/dev/ttyS0:115200", "/dev/ttyS0", 115200),
        ("COM3:57600", "COM3", 57600),
        ("/dev/serial/by-id/usb-Pixhawk6C-if00", "/dev/serial/by-id/usb-Pixhawk6C-if00",
         DEFAULT_SERIAL_BAUD),
    ],
)
def test_serial_urls_parse_to_device_and_baud(url: str, device: str, baud: int) -> None:
    parsed = parse_link_url(url)
    assert (parsed.kind, parsed.device, parsed.baud) == ("serial", device, baud)


@pytest.mark.parametrize(
    ("url", "speed", "loop"),
    [
        ("tlog:/data/a.tlog", 1.0, False),
        ("tlog:/data/a.tlog?speed=2.5", 2.5, False),
        ("tlog:rel/a.tlog?speed=4&loop=1", 4.0, True),
    ],
)
def test_tlog_url_carries_path_speed_and_loop(url: str, speed: float, loop: bool) -> None:
    address = parse_link_url(url)
    assert address.kind == "tlog"
    assert address.path == url.removeprefix("tlog:").partition("?")[0]
    assert (address.replay_speed, address.replay_loop) == (speed, loop)


@pytest.mark.parametrize(
    ("url", "complaint"),
    [
        ("", "empty"),
        ("udpin:127.0.0.1", "missing port"),
        ("udpout::24540", "missing host"),
        ("tcp:host:http", "not a number"),
        ("udpout:127.0.0.1:0", "outside 1..65535"),
        ("tcpin:127.0.0.1:70000", "outside 0..65535"),
        ("udpin:::1:24540", "brackets"),
        ("udpin:[::1:24540", "IPv6"),
        ("udpbcast:255.255.255.255:24550", "not supported"),
        ("/dev/ttyACM0:12345", "not a standard rate"),
        ("quadcopter", "unrecognised"),
        ("tlog:", "missing file"),
        ("tlog:a.tlog?speed=0", "positive"),
        ("tlog:a.tlog?speed=fast", "not a number"),
        ("tlog:a.tlog?rewind=1", "unknown option"),
    ],
)
def test_bad_urls_are_refused_with_the_reason(url: str, complaint: str) -> None:
    with pytest.raises(LinkUrlError, match=complaint):
        parse_link_url(url)


def test_url_label_is_usable_in_file_names() -> None:
    assert parse_link_url("udpin:127.0.0.1:24540").label == "udpin-127.0.0.1-24540"
    assert parse_link_url("/dev/ttyACM0:57600").label == "serial-ttyACM0"
