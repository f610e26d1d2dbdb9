"""Issue 9, probe 10: the supervisor's control socket bounds what a client can make it buffer and
answers malformed requests; the run's summary counts restarts that failed during start-up."""
import socket
import struct

import msgpack
import pytest

from emos.core.rpc import CONTROL_FRAME
from tests.runtime.helpers import SystemUnderTest

pytestmark = pytest.mark.process

STEADY = """
class Steady(BaseComponent):
    def _execution_step(self):
        self.health_status.set_healthy()

launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[Steady(component_name="steady")])
launcher.bringup()
"""


def _frame(sock: socket.socket) -> dict:
    def exact(n: int) -> bytes:
        data = b""
        while len(data) < n:
            chunk = sock.recv(n - len(data))
            if not chunk:
                raise EOFError("closed")
            data += chunk
        return data

    (n,) = struct.unpack("<I", exact(4))
    return msgpack.unpackb(exact(n), raw=False, strict_map_key=False)


def _connect(system) -> socket.socket:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(10)
    sock.connect(str(system.run_dir / "supervisor.sock"))
    return sock


def test_an_oversized_frame_is_refused_at_once_and_the_supervisor_lives_on(tmp_path):
    system = SystemUnderTest(tmp_path, STEADY).wait_up(components=["steady"])
    try:
        with _connect(system) as sock:
            sock.sendall(struct.pack("<I", 500 << 20) + b"\x00" * 1024)  # announces 500 MB, sends 1 KB
            reply = _frame(sock)
            assert reply["ok"] is False
            assert f"exceeds the limit of {CONTROL_FRAME} B" in reply["error"]
            assert sock.recv(1) == b""  # and the connection is closed
        assert system.state("steady") == "active"
    finally:
        assert system.stop() == 0


def test_a_request_with_an_unhashable_op_gets_an_error_reply(tmp_path):
    system = SystemUnderTest(tmp_path, STEADY).wait_up(components=["steady"])
    try:
        with _connect(system) as sock:
            body = msgpack.packb({"id": 7, "op": [1, 2]})
            sock.sendall(struct.pack("<I", len(body)) + body)
            reply = _frame(sock)
            assert reply == {"id": 7, "ok": False, "error": "malformed request: expected a map with a string 'op', got op=[1, 2]"}
            body = msgpack.packb({"id": 8, "op": "tree"})  # the same connection still works
            sock.sendall(struct.pack("<I", len(body)) + body)
            assert _frame(sock)["ok"] is True
    finally:
        assert system.stop() == 0


def test_the_summary_counts_restarts_that_failed_during_start_up(tmp_path):
    flags = tmp_path / "flags"
    flags.mkdir()
    system = SystemUnderTest(tmp_path, f"""
class Flaky(BaseComponent):
    '''Crashes once when running, then fails to configure twice, then comes up.'''
    def custom_on_configure(self):
        n = len(os.listdir({str(flags)!r}))
        if 1 <= n <= 2:
            open({str(flags)!r} + f"/failed{{n}}", "w").close()
            raise RuntimeError("not yet")
    def custom_on_activate(self):
        self.t0 = time.monotonic()
    def _execution_step(self):
        self.health_status.set_healthy()
        if not os.listdir({str(flags)!r}) and time.monotonic() - self.t0 > 0.2:
            open({str(flags)!r} + "/crashed", "w").close()
            os._exit(1)

c = Flaky(component_name="flaky")
c.config.loop_rate = 20.0
launcher = Launcher(multi_processing=True, max_restarts=10)
launcher.add_pkg(components=[c])
launcher.bringup()
""", duration=4.0)
    assert system.wait_exit(60) == 0
    out = system.output()
    assert "flaky                    restarted after: 1 crash; 2 start(s) failed during start-up" in out, out
