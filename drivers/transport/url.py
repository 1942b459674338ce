"""Transport URLs -> unopened `Transport` objects, by scheme.

* ``serial:///dev/ttyUSB0?baud=115200&parity=N&stopbits=1`` - a serial port (pyserial).
* ``pty:///dev/pts/7?baud=9600`` or a bare ``/dev/pts/7`` - a pty slave (an emulator),
  opened exactly like a serial port.
* ``sim://NAME`` - in-process link to an emulator registered under NAME
  (`drivers.transport.sim`).
"""

from __future__ import annotations

import importlib
from urllib.parse import urlsplit

from drivers.transport.base import Transport

# scheme -> "module:Class". The module is imported only when a URL of its scheme is
# opened, so a bench on sim links never loads pyserial. Each class parses its own URL
# with ``Class.from_url(url)``, raising ValueError naming the offending part.
TRANSPORTS: dict[str, str] = {
    "serial": "drivers.transport.serial_link:SerialTransport",
    "pty": "drivers.transport.serial_link:SerialTransport",
    "sim": "drivers.transport.sim:SimTransport",
}
# A bare absolute path is a device node: a serial port or a pty slave.
_BARE_PATH_SCHEME = "serial"


def _schemes() -> str:
    return ", ".join(f"{scheme}://" for scheme in TRANSPORTS)


def open_transport(url: str) -> Transport:
    """Build the transport a URL names (not yet opened: call ``await t.open()``).

    Raises ValueError naming the offending part (scheme, path, name, query parameter).
    """
    if not isinstance(url, str) or not url:
        raise ValueError(f"transport URL must be a non-empty string, got {url!r}")
    if "://" in url:
        scheme = urlsplit(url).scheme.lower()
    elif url.startswith("/"):
        scheme = _BARE_PATH_SCHEME
    else:
        raise ValueError(
            f"transport URL {url!r} has no scheme; use {_schemes()} or an absolute device path"
        )
    target = TRANSPORTS.get(scheme)
    if target is None:
        raise ValueError(
            f"unsupported transport scheme {scheme!r} in {url!r}; use {_schemes()}"
        )
    module_name, class_name = target.split(":")
    transport: Transport = getattr(importlib.import_module(module_name), class_name).from_url(url)
    return transport
