"""Fast DDS's transports for this process's ROS 2 participant (the bridge's, or a component's
``transport="ros2"`` topics): which ones, their XML profile, and their sizes and timing.

``choose_transports`` is called once per process before rclpy starts: a user's own profile or
``FASTDDS_BUILTIN_TRANSPORTS`` wins; otherwise EMOS writes its profile (``fastdds_profile``)
into the run directory and points Fast DDS at it."""
from __future__ import annotations

import logging
import os
import threading
from pathlib import Path

from emos.transport.context import RunContext

log = logging.getLogger("emos.ros2")

# Fast DDS transports (Ros2Bridge's ``fastdds``, see choose_transports): "udp" (the default), UDP
# only: a SIGKILLed bridge leaves no file, at the cost of UDP's copies, and of losses in the other
# node's socket buffer that the bridge cannot size (slower than shared memory for large messages,
# docs/ros2.md); "shm", shared memory between local processes (as ROS 2 nodes on this host use)
# and UDP. Fast DDS leaves /dev/shm/fastrtps_*
# behind when a process is SIGKILLed; with "shm" the bridge removes the segments of dead
# participants when it starts (fastdds_shm.py), but not yet the port segments that live peers
# still sending to the dead participant re-create (seen in tests/ros2/test_bridge.py's SIGKILL
# test), which is why "udp" stays the default.
FASTDDS_TRANSPORTS = ("udp", "shm")
ENV_FASTDDS_TRANSPORTS = "FASTDDS_BUILTIN_TRANSPORTS"
ENV_FASTDDS_PROFILES = "FASTRTPS_DEFAULT_PROFILES_FILE"  # Fast DDS 2 (Jazzy and older)
ENV_FASTDDS3_PROFILES = "FASTDDS_DEFAULT_PROFILES_FILE"  # Fast DDS 3 (Kilted on): the old name is deprecated there

# Sizes the bridge's participant asks of its transports. Large messages travel as ~64 KB
# fragments, all written in one burst; a fragment that finds no room is lost, and Fast DDS repairs
# it only after its reader's heartbeat-response and its writer's NACK-response delays (5 ms each),
# so every lost fragment costs ~10 ms (measured per stage in docs/ros2.md: a 921,600 B half
# round trip at 12-16 ms where the bridge's own work is ~1 ms).
# * UDP: the kernel's default receive buffer (net.core.rmem_default, 208 KB here) holds about three
#   fragments; the bridge's sockets ask for 8 MiB, which the kernel caps at net.core.rmem_max.
#   Only the receive side: with a large send buffer too, tests/ros2/test_bridge.py's 44 topics
#   at once failed to come back within a minute in 4 runs of 4 at load 50 (that test is
#   load-sensitive: HEAD's bridge passed 2 of 3, the receive buffer alone 1 of 2). A ROS 2
#   node's own receive buffer is its own: what the bridge sends it over UDP can still be lost
#   there (docs/ros2.md, Measured), which shared memory avoids.
# * Shared memory: Fast DDS's default segment is 512 KB, smaller than one 921,600 B image, so a
#   writer reuses the buffers of fragments its reader has not read yet; the bridge's segment
#   (its writers' memory) holds several large messages.
# * A burst whose last fragments and trailing heartbeat are both lost (the other node's small
#   socket buffer, under load) is noticed only at the writer's next periodic heartbeat: 3 s by
#   Fast DDS's default (measured: 921,600 B half round trips of 3 s); the bridge's writers send
#   one every 50 ms while a reader has not acknowledged everything (none otherwise).
# * A lost fragment costs its reader's heartbeat-response delay (when it asks for the fragment
#   again) plus its writer's NACK-response delay (when it re-sends it): Fast DDS's defaults are
#   5 ms each, the 9-10 ms half round trips of 921,600 B seen with ``shm`` (fragments are lost
#   where a buffer is smaller than a burst, e.g. a ROS 2 node's default 512 KB segment, which
#   cannot hold one image, when the bridge is slow to read it). The bridge answers at once on its side of each leg: as a reader it asks as soon
#   as a heartbeat shows a gap, as a writer it re-sends as soon as it is asked; a repair then
#   waits only on the other node's delay (~5 ms; measured: p99 of 80 921,600 B round trips
#   11-13 ms -> 6.2-6.5 ms). (The delays let a writer with many readers merge their requests;
#   a bridged topic has a few.)
HEARTBEAT_PERIOD_NS = 50_000_000
HEARTBEAT_RESPONSE_DELAY_NS = 0
NACK_RESPONSE_DELAY_NS = 0
UDP_SOCKET_BUFFER_BYTES = 8 * 1024 * 1024
SHM_SEGMENT_BYTES = 32 * 1024 * 1024
MIN_SOCKET_BUFFER = 65_536  # Fast DDS's UDP transport needs a buffer of one whole datagram


def socket_buffer(kind: str) -> int | None:
    """The socket buffer to ask for (``kind``: ``rmem``, receiving): ours, capped at what the
    kernel lets an unprivileged process set; None (Fast DDS's default) if that is too small."""
    try:
        most = int(Path(f"/proc/sys/net/core/{kind}_max").read_text())
    except (OSError, ValueError):
        most = UDP_SOCKET_BUFFER_BYTES
    size = min(UDP_SOCKET_BUFFER_BYTES, most)
    return size if size >= MIN_SOCKET_BUFFER else None


def fastdds_profile(shm: bool, loopback_only: bool) -> str:
    """The bridge's Fast DDS XML profile: UDPv4 with a large receive buffer (on 127.0.0.1 only when
    ``loopback_only``), and with ``shm`` Fast DDS's shared-memory transport first, with a large
    segment (see ``SHM_SEGMENT_BYTES``); and its writers' and readers' reliability timing
    (``HEARTBEAT_PERIOD_NS``, ``NACK_RESPONSE_DELAY_NS``, ``HEARTBEAT_RESPONSE_DELAY_NS``). QoS
    policies come from ROS 2 as usual."""
    receive = socket_buffer("rmem")
    buffers = f"\n      <receiveBufferSize>{receive}</receiveBufferSize>" if receive else ""
    where = "\n      <interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList>" if loopback_only else ""
    shm_descriptor = f"""
    <transport_descriptor>
      <transport_id>emos_shm</transport_id>
      <type>SHM</type>
      <segment_size>{SHM_SEGMENT_BYTES}</segment_size>
    </transport_descriptor>""" if shm else ""
    ids = ("<transport_id>emos_shm</transport_id>" if shm else "") + "<transport_id>emos_udp</transport_id>"
    what = ("shared memory between local processes, " if shm else "no shared memory, ") + \
        ("UDP on 127.0.0.1 only" if loopback_only else "UDP") + ", large receive buffers"
    return f"""<?xml version="1.0" encoding="UTF-8" ?>
<!-- Written by the EMOS ROS 2 bridge: {what}. -->
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>{shm_descriptor}
    <transport_descriptor>
      <transport_id>emos_udp</transport_id>
      <type>UDPv4</type>{buffers}{where}
    </transport_descriptor>
  </transport_descriptors>
  <participant profile_name="emos_bridge" is_default_profile="true">
    <rtps>
      <userTransports>{ids}</userTransports>
      <useBuiltinTransports>false</useBuiltinTransports>
    </rtps>
  </participant>
  <data_writer profile_name="emos_bridge_writer" is_default_profile="true">
    <times>
      <heartbeatPeriod><sec>0</sec><nanosec>{HEARTBEAT_PERIOD_NS}</nanosec></heartbeatPeriod>
      <nackResponseDelay><sec>0</sec><nanosec>{NACK_RESPONSE_DELAY_NS}</nanosec></nackResponseDelay>
    </times>
  </data_writer>
  <data_reader profile_name="emos_bridge_reader" is_default_profile="true">
    <times>
      <heartbeatResponseDelay><sec>0</sec><nanosec>{HEARTBEAT_RESPONSE_DELAY_NS}</nanosec></heartbeatResponseDelay>
    </times>
  </data_reader>
</profiles>
"""


# The loopback-UDP profile, also given to the tests' and the benchmark's rclpy peers that must
# talk like the bridge.
UDP_LOOPBACK_PROFILE = fastdds_profile(shm=False, loopback_only=True)


def users_profile() -> str | None:
    return os.environ.get(ENV_FASTDDS_PROFILES) or os.environ.get(ENV_FASTDDS3_PROFILES)


def _sweep_leftovers() -> None:
    from emos.interop.ros2.fastdds_shm import remove_leftovers

    removed = remove_leftovers()
    if removed:
        log.info("ROS 2: removed %d Fast DDS shared-memory file(s) no live process used: %s", len(removed), ", ".join(sorted(removed)))


def choose_transports(ctx: RunContext, fastdds: str) -> str:
    """Set up this process's Fast DDS transports for ``fastdds`` (``FASTDDS_TRANSPORTS``);
    returns what was chosen, for the log.

    A user's own Fast DDS profile file (or ``FASTDDS_BUILTIN_TRANSPORTS``) is used as it is.
    Otherwise the bridge gives Fast DDS its own profile (:func:`fastdds_profile`): ``"udp"``,
    UDP only; ``"shm"``, shared memory and UDP, as ROS 2 nodes on this host use. When discovery
    is limited to this host (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` or the older
    ``ROS_LOCALHOST_ONLY=1``), the profile's UDP is on 127.0.0.1 only (the same reach) and the
    variables are taken out of this process's environment: with them rmw_fastrtps installs its
    own transports over the profile's."""
    if fastdds not in FASTDDS_TRANSPORTS:
        raise ValueError(f"ROS 2: fastdds must be one of {FASTDDS_TRANSPORTS}, got {fastdds!r}")
    users = users_profile()
    if users:
        return f"Fast DDS profile {users} (the user's)"
    localhost = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").upper() == "LOCALHOST" or os.environ.get("ROS_LOCALHOST_ONLY") == "1"
    if os.environ.get(ENV_FASTDDS_TRANSPORTS) and not localhost:
        return f"Fast DDS transports {os.environ[ENV_FASTDDS_TRANSPORTS]} (the user's)"
    if fastdds == "shm":
        _sweep_leftovers()
        # Files younger than MIN_AGE_S are skipped (a participant may not have locked them yet),
        # so a predecessor SIGKILLed within seconds of its start, and restarted at once by the
        # supervisor, would leave its files for good: sweep once more when they are old enough.
        from emos.interop.ros2.fastdds_shm import MIN_AGE_S

        later = threading.Timer(MIN_AGE_S + 1.0, _sweep_leftovers)
        later.daemon = True
        later.start()
    path = ctx.run_dir / f"ros2_fastdds_{fastdds}{'_loopback' if localhost else ''}.xml"
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_text(fastdds_profile(shm=fastdds == "shm", loopback_only=localhost))
    os.replace(tmp, path)
    from emos.interop.ros2.env import find

    install = find()
    fastdds2 = install is None or install.distro in ("humble", "iron", "jazzy")
    os.environ[ENV_FASTDDS_PROFILES if fastdds2 else ENV_FASTDDS3_PROFILES] = str(path)
    os.environ.pop("ROS_AUTOMATIC_DISCOVERY_RANGE", None)
    os.environ.pop("ROS_LOCALHOST_ONLY", None)
    reach = "UDP on 127.0.0.1 only (discovery range LOCALHOST)" if localhost else "UDP"
    memory = f"shared memory ({SHM_SEGMENT_BYTES >> 20} MiB segment) between local processes and " if fastdds == "shm" else ""
    return f"Fast DDS {memory}{reach}, receive buffers {socket_buffer('rmem')} B (profile {path})"
