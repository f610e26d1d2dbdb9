"""Is this address this machine, and is this request from our own page? One home for the checks
every EMOS server makes (the web UI, the model server, the Foxglove gate, Zenoh's defaults)."""
from __future__ import annotations

import ipaddress
from urllib.parse import urlsplit

__all__ = ["LOOPBACK_NAMES", "is_loopback", "host_of", "same_origin"]

#: the names a request to a loopback-bound server may give in its ``Host`` header
LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")


def is_loopback(host: str) -> bool:
    """Whether ``host`` (a name or an address, IPv6 with or without brackets) only reaches this
    machine: ``localhost``, 127.0.0.0/8 or ::1. Another host name may resolve to anything: no."""
    host = host.strip()
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def host_of(host_header: str) -> str:
    """The host part of a ``Host`` header (``name``, ``name:port``, ``[v6]:port``, a bare v6)."""
    host = host_header.strip()
    if host.startswith("["):
        return host[1:host.find("]")] if "]" in host else host
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


def same_origin(origin: str, host_header: str) -> bool:
    """Whether an ``Origin`` header names the page a request was made to (scheme http(s), the
    host and port of its ``Host``). ``null`` (sandboxed frames, local files) and anything
    unparsable are foreign."""
    try:
        parts = urlsplit(origin)
    except ValueError:
        return False
    return parts.scheme in ("http", "https") and bool(host_header) and parts.netloc.lower() == host_header.strip().lower()
