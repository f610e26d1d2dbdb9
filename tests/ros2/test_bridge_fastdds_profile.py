"""The bridge's Fast DDS participant as large messages need it (issue 35's 1.25x goal).

Per-stage stamps of ``emos bench ros2`` (docs/ros2.md) showed 921,600 B half round trips of
12-16 ms where the bridge's own work is ~1 ms: Fast DDS lost fragments and repaired them ~10 ms
later. Received over UDP, they overflowed the bridge's kernel-default socket buffer (208 KB, about
three 64 KB fragments); sent over shared memory, they overran Fast DDS's default 512 KB segment.
These tests read what the bridge's real participant got from the kernel and from Fast DDS (its
sockets' receive buffer sizes, its mapped segment's size): counts, not times.
"""
from __future__ import annotations

import os
import socket
from pathlib import Path

import pytest

from tests.ros2.conftest import fastdds_files, fastdds_names, forked_child_result, free_domains

pytestmark = pytest.mark.process


def _udp_buffers() -> list[tuple[int, int, int]]:
    """(port, SO_RCVBUF, SO_SNDBUF) of this process's UDP sockets bound to a port."""
    found = []
    for fd in os.listdir("/proc/self/fd"):
        try:
            if not os.readlink(f"/proc/self/fd/{fd}").startswith("socket:"):
                continue
            sock = socket.socket(fileno=os.dup(int(fd)))
        except OSError:
            continue
        with sock:
            if sock.type != socket.SOCK_DGRAM or sock.family != socket.AF_INET:
                continue
            port = sock.getsockname()[1]
            if port:
                found.append((port, sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF), sock.getsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF)))
    return found


def _segments() -> dict[str, int]:
    """Fast DDS shared-memory files this process maps, and the bytes mapped of each."""
    sizes: dict[str, int] = {}
    with open("/proc/self/maps") as f:
        for line in f:
            parts = line.split()
            if len(parts) >= 6 and parts[5].startswith("/dev/shm/fastrtps_"):
                start, end = (int(x, 16) for x in parts[0].split("-"))
                sizes[parts[5]] = sizes.get(parts[5], 0) + end - start
    return sizes


def _bridge_child(domain: int, fastdds: str) -> dict:
    """In a forked child: a run and a bridge; its participant's sockets and segments."""
    from emos.interop.ros2.bridge import Ros2Bridge
    from emos.transport.context import RunContext

    ctx = RunContext.create()
    bridge = None
    try:
        bridge = Ros2Bridge(ctx, topics=["/profile_check/none"], domain_id=domain, node_name="profile_check_bridge", fastdds=fastdds)
        return {"udp": _udp_buffers(), "segments": _segments(), "transport": bridge.transport}
    finally:
        if bridge is not None:
            bridge.close()
        ctx.remove_everything()


def _run_bridge(fastdds: str) -> dict:
    (domain,) = free_domains(1)
    return forked_child_result(_bridge_child, domain, fastdds, what="the bridge's child")


def _wanted_buffer() -> int:
    """What a socket of the bridge must at least have: 1 MiB (16 fragments), or as much as the
    kernel lets a process set (net.core.rmem_max) when that is less."""
    most = int(Path("/proc/sys/net/core/rmem_max").read_text())
    default = int(Path("/proc/sys/net/core/rmem_default").read_text())
    if most <= default:
        pytest.skip(f"this kernel lets no process have a socket buffer above its default ({default} B): net.core.rmem_max")
    return min(1 << 20, most)


@pytest.mark.parametrize("fastdds", ["udp", "shm"])
def test_the_bridge_receives_udp_with_large_socket_buffers(fastdds):
    wanted = _wanted_buffer()
    before = fastdds_names()
    got = _run_bridge(fastdds)
    udp = got["udp"]
    assert udp, f"no UDP socket of the bridge's participant found ({got['transport']})"
    # Linux reports twice what was set. The sockets Fast DDS listens on (discovery, user data)
    # have the large buffer; the kernel's default is 208 KB.
    receiving = [r for _port, r, _s in udp if r >= wanted]
    assert len(receiving) >= 2, (f"socket buffers (port, SO_RCVBUF, SO_SNDBUF) {udp}, wanted >= {wanted} B", got["transport"])
    assert fastdds_files() - before == set(), "the bridge left Fast DDS files behind"


def test_the_bridges_shared_memory_segment_holds_several_large_messages():
    before = fastdds_names()
    got = _run_bridge("shm")
    own = {name: size for name, size in got["segments"].items() if "_port" not in name}
    # Fast DDS's default segment is 512 KB: less than one 921,600 B image.
    assert own and max(own.values()) >= 4 * 921_600, (f"shared-memory segments mapped: {got['segments']}", got["transport"])
    assert fastdds_files() - before == set(), "the bridge left Fast DDS files behind"
