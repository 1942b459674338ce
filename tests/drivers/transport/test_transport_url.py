"""open_transport: URL -> transport type and settings; bad URLs name the bad part."""

from __future__ import annotations

import pytest

from drivers.transport import open_transport
from drivers.transport.serial_link import SerialTransport
from drivers.transport.sim import SimTransport


def test_serial_url_with_options() -> None:
    t = open_transport("serial:///dev/ttyUSB0?baud=9600&parity=e&stopbits=2")
    assert isinstance(t, SerialTransport)
    assert (t.port, t.baud, t.parity, t.stopbits) == ("/dev/ttyUSB0", 9600, "E", 2)
    assert t.url == "serial:///dev/ttyUSB0?baud=9600&parity=e&stopbits=2"


def test_pty_url_and_bare_path_default_to_115200() -> None:
    for url in ("pty:///dev/pts/7", "/dev/pts/7"):
        t = open_transport(url)
        assert isinstance(t, SerialTransport)
        assert (t.port, t.baud) == ("/dev/pts/7", 115200)


def test_sim_url() -> None:
    t = open_transport("sim://valves")
    assert isinstance(t, SimTransport)
    assert t.name == "valves"


@pytest.mark.parametrize(
    ("url", "names"),
    [
        ("tcp://host:1", "'tcp'"),
        ("ttyUSB0", "no scheme"),
        ("", "non-empty"),
        ("serial://", "no device path"),
        ("serial://dev/ttyUSB0", "'dev'"),
        ("serial:///dev/ttyUSB0?baud=fast", "baud"),
        ("serial:///dev/ttyUSB0?baud=0", "baud"),
        ("serial:///dev/ttyUSB0?speed=9600", "'speed'"),
        ("serial:///dev/ttyUSB0?parity=X", "parity"),
        ("pty:///dev/pts/1?stopbits=3", "stopbits"),
        ("sim://", "no device name"),
        ("sim://x/y", "no path or query"),
    ],
)
def test_bad_urls_raise_value_error_naming_the_part(url: str, names: str) -> None:
    with pytest.raises(ValueError, match=names):
        open_transport(url)
