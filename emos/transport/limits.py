"""How long names may be, derived from the operating system's limits on what they become.

A component name becomes a Unix socket ``<runtime root>/<run id>/ctl/<name>.sock`` (bound first
as ``.<name>.sock.<pid>``, then renamed); a topic name becomes part of a shared-memory segment
``/dev/shm/emos.<run id>.<topic>.<publisher>.g<generation>``. The kernel limits both:

* ``sun_path``: 108 bytes including the terminating NUL, so 107 bytes of path;
* ``NAME_MAX``: 255 bytes for one file name (a segment is a file in ``/dev/shm``).

Checking names against these at definition time turns an ``AF_UNIX path too long`` or
``ENAMETOOLONG`` at start-up into an error that names the component or topic and the limit.
The run id is not known before the run starts, so its longest form is assumed.
"""
from __future__ import annotations

import functools
import os

from emos.transport.context import ENV_RUNTIME_DIR, SHM_PREFIX, encode_name, runtime_root

SUN_PATH_MAX = 107  # sizeof(sockaddr_un.sun_path) = 108, minus the NUL
NAME_MAX = 255
# "<pid>-<start time in 1/100 s>": pid_max is at most 2**22 (7 digits); the start time has 12
# digits until the year 2286.
RUN_ID_MAX = 7 + 1 + 12
_PID_DIGITS = 7
# Generations count ring growths (doubling from 64 KiB to the 512 MiB message limit) across
# restarts; five digits is far more than a run reaches.
_GENERATION_DIGITS = 5
# ``pid<pid>-<id(self) in hex>``: the id of an anonymous publisher (``emos topic pub``).
ANONYMOUS_PUBLISHER_MAX = 3 + _PID_DIGITS + 1 + 16


@functools.lru_cache(maxsize=8)
def _root_bytes(emos_runtime_dir: str | None, xdg_runtime_dir: str | None) -> int:
    return len(os.fsencode(str(runtime_root())))


def _runtime_root_bytes() -> int:
    # Cached per $EMOS_RUNTIME_DIR and $XDG_RUNTIME_DIR (what runtime_root() depends on): names
    # are checked on hot paths too (a publish by topic name), and runtime_root() makes and stats
    # directories.
    return _root_bytes(os.environ.get(ENV_RUNTIME_DIR), os.environ.get("XDG_RUNTIME_DIR"))


def socket_name_limit(subdir: str = "ctl") -> int:
    """Longest encoded name whose socket ``<run dir>/<subdir>/<name>.sock`` fits ``sun_path``.

    Includes the temporary name the server binds first, ``.<name>.sock.<pid>``.
    """
    fixed = _runtime_root_bytes() + 1 + RUN_ID_MAX + 1 + len(subdir) + 1
    return SUN_PATH_MAX - fixed - len(".") - len(".sock") - len(".") - _PID_DIGITS


def component_name_limit() -> int:
    return socket_name_limit("ctl")


def segment_name_limit(publisher_id: str | None = None) -> int:
    """Longest encoded topic name whose segments fit ``NAME_MAX`` for ``publisher_id``.

    Without a publisher: for any publisher, a component (whose name is bounded by
    :func:`component_name_limit`) or an anonymous one.
    """
    if publisher_id is None:
        return _any_publisher_limit(os.environ.get("XDG_RUNTIME_DIR"))
    return _topic_limit(len(encode_name(publisher_id)))


@functools.lru_cache(maxsize=8)
def _any_publisher_limit(xdg_runtime_dir: str | None) -> int:
    return _topic_limit(max(component_name_limit(), ANONYMOUS_PUBLISHER_MAX))


def _topic_limit(publisher_bytes: int) -> int:
    fixed = len(SHM_PREFIX) + RUN_ID_MAX + 1 + 1 + publisher_bytes + len(".g") + _GENERATION_DIGITS
    return NAME_MAX - fixed


def check_component_name(name: str) -> None:
    limit = component_name_limit()
    if len(name) > limit:
        raise ValueError(
            f"component_name {name[:24]!r}... is {len(name)} characters; at most {limit} fit: its control socket "
            f"{runtime_root()}/<run id>/ctl/<name>.sock must fit the {SUN_PATH_MAX + 1}-byte AF_UNIX path limit (sun_path)"
        )


def check_topic_name(name: str, publisher_id: str | None = None) -> None:
    if 3 * len(name) <= _TOPIC_FLOOR and (publisher_id is None or 3 * len(publisher_id) <= _PUBLISHER_CEILING):
        return  # fits whatever the runtime root (hot path: no lookups)
    limit = segment_name_limit(publisher_id)
    if 3 * len(name) <= limit:  # encoding at most triples a name: fits without encoding it
        return
    encoded = len(encode_name(name))
    if encoded > limit:
        who = f"publisher {publisher_id!r}" if publisher_id else "any publisher"
        raise ValueError(
            f"topic name {name[:32]!r}... is {encoded} bytes as a file name; at most {limit} fit for {who}: its shared-memory "
            f"segments {SHM_PREFIX}<run id>.<topic>.<publisher>.g<generation> must fit NAME_MAX ({NAME_MAX} bytes)"
        )


def check_socket_name(kind: str, name: str, subdir: str = "srv") -> None:
    """A service or action name, which becomes ``<run dir>/srv/<name>.sock``."""
    encoded = len(encode_name(name))
    limit = socket_name_limit(subdir)
    if encoded > limit:
        raise ValueError(
            f"{kind} name {name[:32]!r}... is {encoded} bytes as a file name; at most {limit} fit: its socket "
            f"{runtime_root()}/<run id>/{subdir}/<name>.sock must fit the {SUN_PATH_MAX + 1}-byte AF_UNIX path limit (sun_path)"
        )


# The smallest topic limit any runtime root allows (a 1-byte root gives the longest component
# names, hence the longest publisher ids): names up to a third of it never need checking.
_PUBLISHER_CEILING = max(SUN_PATH_MAX - (1 + 1 + RUN_ID_MAX + 1 + len("ctl") + 1) - len("..sock.") - _PID_DIGITS, ANONYMOUS_PUBLISHER_MAX)
_TOPIC_FLOOR = _topic_limit(_PUBLISHER_CEILING)
