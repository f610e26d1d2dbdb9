"""The fault-injecting TCP proxy, against a real echo server on loopback."""
import socket
import socketserver
import threading
import time

import pytest

from emos.chaos.nemesis import NemesisError
from emos.chaos.nemesis.proxy import FaultProxy

pytestmark = pytest.mark.unit


class _Echo(socketserver.BaseRequestHandler):
    def handle(self):
        try:
            while data := self.request.recv(65536):
                self.request.sendall(data)
        except (ConnectionResetError, BrokenPipeError):
            pass  # the proxy's reset_peer toxic cuts the upstream side too: expected, not a test failure


@pytest.fixture
def proxy():
    server = socketserver.ThreadingTCPServer(("127.0.0.1", 0), _Echo)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    p = FaultProxy("echo", f"127.0.0.1:{server.server_address[1]}")
    p.start()
    yield p
    p.stop()
    server.shutdown()
    server.server_close()


def _roundtrip(address, payload: bytes, timeout: float = 5.0) -> tuple[bytes, float]:
    t0 = time.monotonic()
    with socket.create_connection(address, timeout=timeout) as s:
        s.sendall(payload)
        got = b""
        while len(got) < len(payload):
            chunk = s.recv(65536)
            if not chunk:
                break
            got += chunk
    return got, time.monotonic() - t0


def test_clean_proxy_forwards_bytes_unchanged(proxy):
    payload = bytes(range(256)) * 100
    got, _ = _roundtrip(proxy.address, payload)
    assert got == payload


def test_latency_delays_both_directions(proxy):
    # The added latency is a lower bound whatever the load; a local round trip without it stays
    # far below the 2 s it adds (a loaded machine delays one by tens of milliseconds, not seconds).
    _, clean = _roundtrip(proxy.address, b"x")
    proxy.set_toxic("latency", latency_ms=1000)
    got, slow = _roundtrip(proxy.address, b"x")
    assert got == b"x" and slow >= 2.0 > clean  # 1 s each way
    proxy.remove_toxic("latency")
    _, again = _roundtrip(proxy.address, b"x")
    assert again < 2.0


def test_down_and_reset_peer_break_connections(proxy):
    proxy.set_toxic("down")
    with pytest.raises((ConnectionError, OSError)):
        got, _ = _roundtrip(proxy.address, b"hello")
        if not got:
            raise ConnectionResetError("closed without an answer")
    proxy.remove_toxic("down")
    proxy.set_toxic("reset_peer", timeout_ms=0)
    with pytest.raises((ConnectionError, OSError)):
        got, _ = _roundtrip(proxy.address, b"hello")
        if not got:
            raise ConnectionResetError("closed without an answer")


def test_garbage_changes_the_answer_and_slicer_keeps_all_bytes(proxy):
    payload = b"A" * 4000
    proxy.set_toxic("slicer", average_size=100, delay_ms=1)
    got, _ = _roundtrip(proxy.address, payload)
    assert got == payload
    proxy.remove_toxic("slicer")
    proxy.set_toxic("garbage")
    got, _ = _roundtrip(proxy.address, payload)
    assert len(got) == len(payload) and got != payload


def test_bad_configuration_is_named():
    with pytest.raises(NemesisError, match="host:port"):
        FaultProxy("m", "nonsense")
    with pytest.raises(NemesisError, match="loopback"):
        FaultProxy("m", "127.0.0.1:80", listen="10.0.0.1:0")
    p = FaultProxy("m", "127.0.0.1:80")
    with pytest.raises(NemesisError, match="unknown toxic 'lag'.*latency"):
        p.set_toxic("lag")


def test_http_error_answers_without_the_upstream(proxy):
    proxy.set_toxic("http_error", status=503)
    with socket.create_connection(proxy.address, timeout=5) as s:
        s.sendall(b"POST /api/chat HTTP/1.1\r\nHost: x\r\nContent-Length: 2\r\n\r\n{}")
        answer = b""
        while chunk := s.recv(4096):
            answer += chunk
    assert answer.startswith(b"HTTP/1.1 503") and b"chaos proxy" in answer
    proxy.remove_toxic("http_error")
    got, _ = _roundtrip(proxy.address, b"hello")
    assert got == b"hello"
