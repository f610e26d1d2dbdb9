"""With no Zenoh configuration file, EMOS's sessions stay on loopback (nothing listens beyond
127.0.0.1, no multicast or other UDP socket) and still meet the sessions of other processes and
runs of this host; a configuration that reaches beyond the host is named in one WARNING."""
import ipaddress
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import uuid
from pathlib import Path

import psutil
import pytest

from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

zenoh = pytest.importorskip("zenoh", reason="the 'net' extra (eclipse-zenoh) is not installed")


@pytest.fixture
def runtime_dir(monkeypatch):
    """A private EMOS runtime directory (short: run sockets live under it), so the loopback
    sessions of this test meet only each other, not those of whatever else runs here."""
    path = tempfile.mkdtemp(prefix="emz-")
    monkeypatch.setenv("EMOS_RUNTIME_DIR", path)
    monkeypatch.delenv("EMOS_ZENOH_CONFIG", raising=False)
    monkeypatch.setenv("EMOS_NET_GROUP", f"t{uuid.uuid4().hex[:10]}")
    yield path
    shutil.rmtree(path, ignore_errors=True)


def _beyond_loopback(pid: int) -> list[str]:
    """The sockets of ``pid`` another host could reach or that talk to another host: any UDP
    socket (scouting), a TCP listener not on loopback, a TCP connection to a non-loopback peer."""
    found = []
    for c in psutil.Process(pid).net_connections(kind="inet"):
        if c.type == socket.SOCK_DGRAM:
            found.append(f"UDP {c.laddr.ip}:{c.laddr.port}")
        elif c.status == psutil.CONN_LISTEN and not ipaddress.ip_address(c.laddr.ip).is_loopback:
            found.append(f"TCP listening on {c.laddr.ip}:{c.laddr.port}")
        elif c.raddr and not ipaddress.ip_address(c.raddr.ip).is_loopback:
            found.append(f"TCP to {c.raddr.ip}:{c.raddr.port}")
    return found


PROBE = r"""
import json, logging, os, sys, threading, time
logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(levelname)s %(name)s: %(message)s")
from emos.msgs import Int32
from emos.transport import zenoh_net

pub = zenoh_net.ZenohPublisher("/hello", Int32)
sub = zenoh_net.ZenohSubscriber("/hello", Int32, queue_size=100)
print("ready", flush=True)
told = threading.Thread(target=sys.stdin.readline, daemon=True)  # the test says when to stop
told.start()
seen, said, deadline = set(), False, time.monotonic() + 60  # bounds a hang only
while told.is_alive():  # go on publishing for the other probe until told
    pub.publish(Int32(data=os.getpid()))
    time.sleep(0.05)
    seen |= {m.data for m in sub.take()} - {os.getpid()}
    if not said and (seen or time.monotonic() > deadline):
        print("seen " + json.dumps(sorted(seen)), flush=True)
        said = True
zenoh_net.close_sessions()
"""


def _probe() -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", PROBE], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=REPO)


def test_with_no_configuration_file_sessions_listen_on_loopback_only_and_still_meet(runtime_dir):
    probes = [_probe(), _probe()]
    try:
        for p in probes:
            assert p.stdout.readline().strip() == "ready", f"probe {p.pid} did not start (its log is printed below)"
        seen = {}
        for p in probes:
            line = p.stdout.readline().strip()
            assert line.startswith("seen "), f"probe {p.pid}: {line!r}"
            seen[p.pid] = json.loads(line[5:])
            # Both sessions are open and connected to each other here: nothing beyond loopback.
            assert _beyond_loopback(p.pid) == [], f"probe {p.pid}"
        a, b = probes
        assert seen == {a.pid: [b.pid], b.pid: [a.pid]}  # two processes with no file still meet
        entries = [n for n in os.listdir(os.path.join(runtime_dir, "zenoh-peers")) if n.endswith(".json")]
        assert sorted(int(n.split("-")[0]) for n in entries) == sorted([a.pid, b.pid])  # one registration each
    finally:
        errors = [p.communicate("\n", timeout=90)[1] for p in probes]
        for p, err in zip(probes, errors):
            print(f"--- probe {p.pid} log:\n{err}")  # shown by pytest when the test fails
    for p, err in zip(probes, errors):
        assert p.returncode == 0, err
        assert "WARNING" not in err and "opened on loopback only" in err, err
    # Closing the sessions removed their registrations.
    assert [n for n in os.listdir(os.path.join(runtime_dir, "zenoh-peers")) if n.endswith(".json")] == []


WARN_PROBE = r"""
import logging, sys
logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(levelname)s %(name)s: %(message)s")
from emos.transport import zenoh_net
for path in sys.argv[1:]:
    zenoh_net.session(path)
zenoh_net.close_sessions()
"""


def _file(path, listen: str) -> str:
    path.write_text(json.dumps({
        "mode": "peer", "listen": {"endpoints": [listen]},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
    }))
    return str(path)


def test_a_configuration_file_that_listens_beyond_loopback_gives_exactly_one_warning_naming_it(tmp_path, runtime_dir):
    local = _file(tmp_path / "local.json5", "tcp/127.0.0.1:0")
    wide = _file(tmp_path / "wide.json5", "tcp/0.0.0.0:0")
    wider = _file(tmp_path / "wider.json5", "tcp/0.0.0.0:0")
    out = subprocess.run([sys.executable, "-c", WARN_PROBE, local, wide, wider], capture_output=True, text=True, cwd=REPO, timeout=120, check=False)
    assert out.returncode == 0, out.stderr
    warnings = [line for line in out.stderr.splitlines() if line.startswith("WARNING")]
    assert len(warnings) == 1, out.stderr  # once per process, not once per session
    assert "tcp/0.0.0.0:0" in warnings[0] and "wide.json5" in warnings[0]
    assert "TLS" in warnings[0] and "access control" in warnings[0] and "anyone" in warnings[0]
    # A loopback-only file alone warns about nothing.
    quiet = subprocess.run([sys.executable, "-c", WARN_PROBE, local], capture_output=True, text=True, cwd=REPO, timeout=120, check=False)
    assert quiet.returncode == 0 and "WARNING" not in quiet.stderr, quiet.stderr


def test_what_reaches_beyond_the_host_is_read_from_the_effective_configuration(tmp_path):
    from emos.transport import zenoh_config

    # Zenoh's own defaults: every interface, multicast scouting on every multicast interface.
    assert zenoh_config.exposure(zenoh.Config()) == ["listen tcp/[::]:0", "multicast scouting on interface auto (224.0.0.224:7446)"]
    # EMOS's default: nothing.
    assert zenoh_config.exposure(zenoh_config.load_config(zenoh, "")) == []
    assert zenoh_config.exposure(zenoh_config.loopback_config(zenoh, 7000, ["tcp/127.0.0.1:7001"])) == []
    cases = [
        ({"listen": {"endpoints": ["tcp/[::1]:7447", "unixsock-stream//tmp/z.sock"]}, "scouting": {"multicast": {"interface": "lo"}}}, []),
        ({"listen": {"endpoints": ["tcp/127.0.0.1:7447"]}, "connect": {"endpoints": ["tls/robot.lan:7447"]},
          "scouting": {"multicast": {"enabled": False}}}, ["connect tls/robot.lan:7447"]),
        ({"listen": {"endpoints": ["tcp/127.0.0.1:7447"]}, "scouting": {"multicast": {"interface": "eth0", "address": "224.0.0.225:7446"}}},
         ["multicast scouting on interface eth0 (224.0.0.225:7446)"]),
        ({"mode": "client", "connect": {"endpoints": ["tcp/10.0.0.2:7447"]}}, ["connect tcp/10.0.0.2:7447"]),  # a client with endpoints does not scout
        ({"listen": {"endpoints": {"peer": ["tcp/192.168.1.4:0"], "router": ["tcp/127.0.0.1:0"]}}, "scouting": {"multicast": {"enabled": False}}},
         ["listen tcp/192.168.1.4:0"]),
    ]
    for i, (body, expected) in enumerate(cases):
        path = tmp_path / f"c{i}.json5"
        path.write_text(json.dumps(body))
        assert zenoh_config.exposure(zenoh_config.load_config(zenoh, str(path))) == expected, body


PUBLISHER = """
alarm = Topic(name="alarm", msg_type="Int32", transport="zenoh")  # marked for the network

class Worker(BaseComponent):
    def custom_on_activate(self):
        self.n = 0
    def _execution_step(self):
        self.n += 1
        self.publish(alarm, M.Int32(data=self.n))
        self.health_status.set_healthy()

worker = Worker(component_name="worker", outputs=[alarm])
worker.config.loop_rate = 5
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[worker])
launcher.bringup()
"""

READER = """
class Reader(BaseComponent):
    def _execution_step(self):
        msg = self.node.latest("alarm")
        if msg is not None:
            with open("got.tmp", "w") as f:
                f.write(str(msg.data))
            os.replace("got.tmp", "got")
        self.health_status.set_healthy()

reader = Reader(component_name="reader", inputs=[Topic(name="alarm", msg_type="Int32")])
reader.config.loop_rate = 10
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[reader])
launcher.bringup()
"""


def test_two_runs_with_no_configuration_file_exchange_a_topic_over_loopback_only(tmp_path, runtime_dir):
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    reader = SystemUnderTest(b, READER, env={"EMOS_NET_TOPICS": "all"}).wait_up(components=["reader"], timeout=60)
    worker = None
    try:
        worker = SystemUnderTest(a, PUBLISHER).wait_up(components=["worker"], timeout=60)
        assert worker.ctx.run_id != reader.ctx.run_id
        wait_until(lambda: (b / "got").exists() and int((b / "got").read_text() or 0) >= 2, timeout=60, what="run A's topic in run B")
        for run in (worker, reader):
            for pid in (run.pid("worker") or run.pid("reader"), run.proc.pid):
                assert _beyond_loopback(pid) == [], f"pid {pid}"
        assert "WARNING emos.transport.zenoh" not in worker.output() + reader.output()
    finally:
        if worker is not None:
            assert worker.stop() == 0
        assert reader.stop() == 0
    assert reader.leftovers() == [] and worker.leftovers() == []


def test_registrations_of_closed_sessions_and_dead_processes_are_removed_and_only_loopback_is_read(runtime_dir):
    from emos.transport import zenoh_net

    folder = os.path.join(runtime_dir, "zenoh-peers")
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True, check=True)
    os.makedirs(folder, mode=0o700, exist_ok=True)
    stale = os.path.join(folder, f"{dead.stdout.strip()}-1.json")  # a process that died without closing its session
    with open(stale, "w") as f:
        json.dump({"pid": int(dead.stdout), "token": 1, "endpoint": "tcp/127.0.0.1:1"}, f)
    try:
        first = zenoh_net.session("")
        assert not os.path.exists(stale)
        def mine() -> list[str]:
            return [n for n in os.listdir(folder) if n.startswith(f"{os.getpid()}-")]

        assert len(mine()) == 1
        first.close()  # closed behind zenoh_net's back: the next call opens and registers anew
        second = zenoh_net.session("")
        assert second is not first and len(mine()) == 1
        # A registration of a live process that names anything but a loopback TCP endpoint is
        # never connected to (the entry claims this test's parent process, which is alive).
        from emos.transport.context import _start_token
        from emos.transport.zenoh_config import _live_peers

        parent = os.getppid()
        with open(os.path.join(folder, f"{parent}-7447.json"), "w") as f:
            json.dump({"pid": parent, "token": _start_token(parent), "endpoint": "tcp/192.0.2.7:7447"}, f)
        assert _live_peers(Path(folder)) == []
    finally:
        zenoh_net.close_sessions()
    assert [n for n in os.listdir(folder) if n.startswith(f"{os.getpid()}-")] == []
