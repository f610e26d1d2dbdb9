"""Why EMOS turns Zenoh's own shared memory off (docs/network.md, "Zenoh's own shared memory is
off"): a receiving process stays up while a sending process is started three times, each time
putting twenty 1 MiB messages over loopback TCP; after each sender has exited, print the
receiver's locked memory (VmLck), its RSS, how many Zenoh segments it still maps, and how many
Zenoh segment files are in /dev/shm. Plain eclipse-zenoh, no EMOS code::

    python3 scripts/zenoh_shm_growth.py on    # Zenoh's default: shared memory on
    python3 scripts/zenoh_shm_growth.py off   # what EMOS's sessions use

Leaves the "on" run's segment files in /dev/shm (Zenoh removes them when the next Zenoh session
with shared memory on starts).
"""
import json
import os
import socket
import subprocess
import sys
import tempfile
import time

import zenoh

KEY = "shmgrowth/x"


def _send(config: str) -> None:
    session = zenoh.open(zenoh.Config.from_file(config))
    publisher = session.declare_publisher(KEY)
    for _ in range(20):
        publisher.put(bytes(1 << 20))
        time.sleep(0.05)
    session.close()


def _status() -> str:
    with open("/proc/self/status") as f:
        fields = {line.split(":")[0]: line.split()[1] for line in f if line.startswith(("VmLck", "VmRSS"))}
    with open("/proc/self/maps") as f:
        maps = sum(1 for line in f if ".zenoh" in line)
    files = sum(1 for name in os.listdir("/dev/shm") if name.endswith(".zenoh"))
    return f"VmLck {fields['VmLck']} kB, VmRSS {fields['VmRSS']} kB, Zenoh segments mapped {maps}, segment files in /dev/shm {files}"


def main(mode: str) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    folder = tempfile.mkdtemp(prefix="zenoh-shm-growth-")
    common = {"mode": "peer", "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
              "transport": {"shared_memory": {"enabled": mode == "on"}}}
    receiver_conf, sender_conf = os.path.join(folder, "receiver.json5"), os.path.join(folder, "sender.json5")
    with open(receiver_conf, "w") as f:
        json.dump({**common, "listen": {"endpoints": [f"tcp/127.0.0.1:{port}"]}}, f)
    with open(sender_conf, "w") as f:
        json.dump({**common, "connect": {"endpoints": [f"tcp/127.0.0.1:{port}"]}}, f)
    session = zenoh.open(zenoh.Config.from_file(receiver_conf))
    received = []
    subscriber = session.declare_subscriber(KEY, lambda sample: received.append(len(sample.payload.to_bytes())))
    print(f"shared memory {mode}, receiver at start: {_status()}", flush=True)
    for generation in range(1, 4):
        subprocess.run([sys.executable, __file__, "--send", sender_conf], check=True, timeout=60)
        time.sleep(0.5)
        print(f"after sender {generation} exited ({len(received)} messages received): {_status()}", flush=True)
    subscriber.undeclare()
    session.close()
    os._exit(0)  # Zenoh's threads can hold a normal exit


if __name__ == "__main__":
    if sys.argv[1] == "--send":
        _send(sys.argv[2])
    elif sys.argv[1] in ("on", "off"):
        main(sys.argv[1])
    else:
        sys.exit("usage: zenoh_shm_growth.py on|off")
