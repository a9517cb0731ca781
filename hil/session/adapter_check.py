"""The adapter check at session start (docs/adapters.md): on a ``serial:`` or ``can:`` link,
or any link with a modelled wire (``wire=``), what the port is and what its latency allows.

One warning on stderr naming the adapter, its latency and the fix when it caps the lockstep
rate (an FTDI latency timer above 1 ms, a slow CAN bitrate); the log's metadata gets an
``adapter`` record of the adapter and its settings either way.
"""
from __future__ import annotations

import re
import sys

from hil.links import adapters
from hil.links.adapters import AdapterInfo


def checked_link(spec: str) -> bool:
    """A link to a real board's port (or one with a modelled wire)."""
    return (spec.startswith(("serial:", "can:", "/dev/"))
            or re.search(r"[?&]wire=", spec) is not None)


def check_adapter(spec: str, conn, log=None, warn=None) -> AdapterInfo | None:
    """Inspects the session's link (sysfs under adapters.SYSFS_ROOT), warns once, records it
    in ``log``'s metadata. None for a link that is not checked."""
    if not checked_link(spec):
        return None
    info = adapters.inspect_link(spec, adapters.SYSFS_ROOT, wire=getattr(conn, "wire", None))
    link = getattr(conn.link, "link", conn.link)          # under a link tap, the link itself
    descriptor = getattr(link, "descriptor", None)
    if info.kind not in ("pty", "process"):
        info.low_latency = adapters.read_low_latency(descriptor() if descriptor else None)
    text = adapters.warning(info)
    if text is not None:
        (warn or _print_warning)(text)
    if log is not None:
        log.add_metadata("adapter", info.metadata())
    return info


def _print_warning(text: str) -> None:
    print(f"hil: warning: {text}", file=sys.stderr)
