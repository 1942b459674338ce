"""Transport URLs -> unopened `Transport` objects.

* ``serial:///dev/ttyUSB0?baud=115200&parity=N&stopbits=1`` - a serial port (pyserial).
* ``pty:///dev/pts/7?baud=9600`` or a bare ``/dev/pts/7`` - a pty slave (an emulator),
  opened exactly like a serial port.
* ``sim://NAME`` - in-process link to an emulator registered under NAME
  (`drivers.transport.sim`).
"""

from __future__ import annotations

from urllib.parse import parse_qsl, urlsplit

from drivers.transport.base import Transport
from drivers.transport.serial_link import SerialTransport
from drivers.transport.sim import SimTransport

DEFAULT_BAUD = 115200
_SERIAL_PARAMS = ("baud", "parity", "stopbits")


def _serial_options(url: str, query: str) -> dict[str, object]:
    options: dict[str, object] = {}
    for key, value in parse_qsl(query, keep_blank_values=True, strict_parsing=False):
        if key not in _SERIAL_PARAMS:
            raise ValueError(
                f"unknown query parameter {key!r} in transport URL {url!r}; "
                f"known: {', '.join(_SERIAL_PARAMS)}"
            )
        if key == "baud":
            if not value.isdigit() or int(value) <= 0:
                raise ValueError(f"baud must be a positive integer, got {value!r} in {url!r}")
            options["baud"] = int(value)
        elif key == "parity":
            if value.upper() not in ("N", "E", "O"):
                raise ValueError(f"parity must be N, E or O, got {value!r} in {url!r}")
            options["parity"] = value.upper()
        else:
            if value not in ("1", "2"):
                raise ValueError(f"stopbits must be 1 or 2, got {value!r} in {url!r}")
            options["stopbits"] = int(value)
    return options


def open_transport(url: str) -> Transport:
    """Build the transport a URL names (not yet opened: call ``await t.open()``).

    Raises ValueError naming the offending part (scheme, path, name, query parameter).
    """
    if not isinstance(url, str) or not url:
        raise ValueError(f"transport URL must be a non-empty string, got {url!r}")
    if "://" not in url:
        if url.startswith("/"):
            return SerialTransport(url, url, DEFAULT_BAUD)
        raise ValueError(
            f"transport URL {url!r} has no scheme; use serial://, pty://, sim:// "
            "or an absolute device path"
        )
    parts = urlsplit(url)
    scheme = parts.scheme.lower()
    if scheme in ("serial", "pty"):
        if parts.netloc:
            raise ValueError(
                f"{scheme} URL {url!r} has host part {parts.netloc!r}; "
                f"write {scheme}:///dev/... (three slashes)"
            )
        if not parts.path or parts.path == "/":
            raise ValueError(f"{scheme} URL {url!r} has no device path")
        options = _serial_options(url, parts.query)
        return SerialTransport(url, parts.path, **options)  # type: ignore[arg-type]
    if scheme == "sim":
        if not parts.netloc:
            raise ValueError(f"sim URL {url!r} has no device name (sim://NAME)")
        if parts.path not in ("", "/") or parts.query:
            raise ValueError(f"sim URL {url!r} must be just sim://NAME, no path or query")
        return SimTransport(url, parts.netloc)
    raise ValueError(
        f"unsupported transport scheme {parts.scheme!r} in {url!r}; "
        "use serial://, pty:// or sim://"
    )
