"""open_transport: URL -> transport type and settings; bad URLs name the bad part."""

from __future__ import annotations

import subprocess
import sys

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


def test_transports_are_imported_only_when_their_scheme_is_opened() -> None:
    """A sim-only process never loads pyserial, the pty server or the test doubles."""
    probe = (
        "import sys\n"
        "from drivers.transport import open_transport\n"
        "open_transport('sim://x')\n"
        "print(sorted(m for m in ('serial', 'drivers.transport.serial_link', 'drivers.transport.pty',"
        " 'drivers.testing') if m in sys.modules))\n"
        "open_transport('serial:///dev/ttyUSB0')\n"
        "print('serial' in sys.modules)\n"
    )
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, timeout=60)
    assert result.stdout.split("\n")[:2] == ["[]", "True"]
