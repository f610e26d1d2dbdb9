"""Issue 9, probes 8 and 10: the CLI against a live system: signals, pipes, wrong types, ports."""
import os
import signal
import socket
import subprocess
import sys
import time

import pytest

from emos.msgs import Image
from emos.transport.pubsub import Publisher
from tests.runtime.helpers import HANG_S, LISTENER, SystemUnderTest, ctrl_c_as_at_a_terminal, wait_until

pytestmark = pytest.mark.process



def _emos(*args: str, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "emos", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=ctrl_c_as_at_a_terminal, **kw)


@pytest.fixture
def system(tmp_path):
    s = SystemUnderTest(tmp_path, LISTENER).wait_up(components=["listener"])
    yield s
    assert s.stop() == 0
    assert s.leftovers() == []


def _fifos(system) -> set[str]:
    """Wake-up FIFOs and their state pages."""
    return {p.name for p in (system.run_dir / "wake").iterdir()}


def _segments(system, topic_token: str) -> list[str]:
    return [n for n in os.listdir("/dev/shm") if n.startswith(system.ctx.shm_prefix + topic_token + ".")]


def test_sigterm_to_topic_echo_removes_its_wakeup_fifo(system):
    before = _fifos(system)
    echo = _emos("topic", "echo", "/listener/status", "--run", system.run_dir.name)
    # Wait for the FIFO itself (made after its state page): then the echo is past its set-up.
    wait_until(lambda: any(not n.endswith(".state") for n in _fifos(system) - before), what="the echo's FIFO")
    echo.send_signal(signal.SIGTERM)
    out, err = echo.communicate(timeout=HANG_S)
    assert echo.returncode == 143, err
    assert "Traceback" not in err
    assert _fifos(system) == before


def test_ctrl_c_on_topic_echo_exits_130_without_a_traceback(system):
    echo = _emos("topic", "echo", "/listener/status", "--run", system.run_dir.name)
    wait_until(lambda: echo.stdout.readline().strip() != "", what="a first message")
    echo.send_signal(signal.SIGINT)
    _, err = echo.communicate(timeout=HANG_S)
    assert echo.returncode == 130 and "Traceback" not in err, err


def test_topic_echo_into_a_closed_pipe_exits_quietly(system):
    cmd = f"{sys.executable} -m emos topic echo /listener/status --run {system.run_dir.name} | head -n 1"
    out = subprocess.run(["bash", "-o", "pipefail", "-c", cmd], capture_output=True, text=True, timeout=30)
    assert out.returncode == 141, out.stderr
    assert "Traceback" not in out.stderr and "BrokenPipe" not in out.stderr


def test_emos_status_into_a_closed_pipe_exits_quietly(system):
    cmd = f"{sys.executable} -m emos status --watch 0.05 --run {system.run_dir.name} | head -n 1"
    out = subprocess.run(["bash", "-o", "pipefail", "-c", cmd], capture_output=True, text=True, timeout=30)
    assert out.returncode == 141, out.stderr
    assert "Traceback" not in out.stderr and "BrokenPipe" not in out.stderr


def test_sigterm_to_topic_pub_removes_its_ring(system):
    pub = _emos("topic", "pub", "/shared", "String", '{"data": "hi"}', "--rate", "20", "--count", "0", "--run", system.run_dir.name)
    wait_until(lambda: _segments(system, "shared"), what="the CLI's ring")
    pub.send_signal(signal.SIGTERM)
    _, err = pub.communicate(timeout=HANG_S)
    assert pub.returncode == 143 and "Traceback" not in err, err
    assert _segments(system, "shared") == [], err


def test_topic_pub_refuses_a_type_the_topic_does_not_carry(system):
    system.ctx.subscriber_dir("/shared")
    good = _emos("topic", "pub", "/shared", "String", '{"data": "hi"}', "--rate", "20", "--count", "0", "--run", system.run_dir.name)
    try:
        wait_until(lambda: _segments(system, "shared"), what="the String publisher")
        bad = _emos("topic", "pub", "/shared", "Int64", '{"data": 1}', "--run", system.run_dir.name)
        _, err = bad.communicate(timeout=30)
        assert bad.returncode != 0
        assert "/shared carries std_msgs/msg/String" in err and "not std_msgs/msg/Int64" in err
    finally:
        good.terminate()
        good.communicate(timeout=HANG_S)


def test_a_wrong_type_publisher_is_ignored_and_reported_once_with_a_count(system):
    pub = Publisher(system.ctx, "/shared", Image)  # bypasses the CLI's check, as a buggy peer would
    try:
        time.sleep(3.0)  # the subscriber rescans every second
        assert system.state("listener") == "active"
    finally:
        pub.close()
    out = system.output()
    assert "Traceback" not in out and "TopicTypeError" not in out
    assert out.count("ignoring publisher") == 1
    assert "sends sensor_msgs/msg/Image where this subscriber expects std_msgs/msg/String (seen 1 time(s))" in out


def test_serve_models_validates_ports_at_argument_parsing():
    out = subprocess.run([sys.executable, "-m", "emos", "serve", "models", "--port", "70000"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2
    assert "port number 1-65535" in out.stderr and "Traceback" not in out.stderr


def test_serve_models_names_the_resp_port_that_is_busy():
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    port = busy.getsockname()[1]
    try:
        out = subprocess.run([sys.executable, "-m", "emos", "serve", "models", "--port", "0", "--resp-port", str(port)],
                             capture_output=True, text=True, timeout=120)
    finally:
        busy.close()
    assert out.returncode == 1
    assert f"cannot listen on 127.0.0.1:{port} for the RESP server: address in use" in out.stderr, out.stderr


def _helpers_of(token: str) -> list[int]:
    import psutil

    found = []
    for p in psutil.process_iter():
        try:
            if p.environ().get("EMOS_HARDENING_TOKEN") == token and p.status() != psutil.STATUS_ZOMBIE:
                found.append(p.pid)
        except psutil.Error:
            pass
    return found


@pytest.mark.parametrize("mode", ["transport", "component"])
def test_ctrl_c_at_the_terminal_ends_emos_bench_quietly_with_its_helpers(mode):
    token = f"bench-{os.getpid()}-{mode}"
    bench = subprocess.Popen(
        [sys.executable, "-m", "emos", "bench", "ipc", "--mode", mode, "--sizes", "8", "--messages", "200000", "--transports", "emos"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True, preexec_fn=ctrl_c_as_at_a_terminal,
        env={**os.environ, "EMOS_HARDENING_TOKEN": token},
    )
    try:
        wait_until(lambda: len(_helpers_of(token)) >= 2, timeout=30, what="the benchmark and its helpers")
        time.sleep(1.0)
        os.killpg(bench.pid, signal.SIGINT)  # what a terminal's Ctrl-C does: the whole foreground group
        _, err = bench.communicate(timeout=60)
    finally:
        if bench.poll() is None:
            os.killpg(bench.pid, signal.SIGKILL)
            bench.wait()
    assert bench.returncode == 130, err
    assert "Traceback" not in err, err
    wait_until(lambda: _helpers_of(token) == [], timeout=HANG_S, what="the benchmark's helpers to end")


def test_ctrl_c_ends_serve_models_cleanly():
    serve = _emos("serve", "models", "--port", "0")
    try:
        wait_until(lambda: "emos-model-server ready" in serve.stdout.readline(), timeout=60, what="the server")
        serve.send_signal(signal.SIGINT)
        _, err = serve.communicate(timeout=30)
    finally:
        if serve.poll() is None:
            serve.kill()
            serve.wait()
    assert serve.returncode == 130 and "Traceback" not in err, err  # 128 + SIGINT, after a clean shutdown


def test_the_sigterm_handler_imports_nothing():
    """A SIGTERM that lands while a command's modules are still being imported must not import
    inside that import: the handler did (`emos.tools.cli.common`), and under load the echo below
    died of a circular import ("cannot access submodule 'futures' of module 'concurrent'"), exit
    1 with a traceback instead of 143."""
    code = ("import sys\n"
            "from emos.tools.cli import _terminated\n"
            "assert 'emos.tools.cli.common' not in sys.modules\n"
            "try:\n"
            "    _terminated(15, None)\n"
            "except SystemExit as exc:\n"
            "    print(exc.code, 'emos.tools.cli.common' in sys.modules)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["143", "False"], done.stdout


def test_sigterm_at_any_moment_of_topic_echo_leaves_nothing(system):
    """SIGTERM early, while the echo is still setting up, leaves no half-made FIFO either."""
    before = _fifos(system)
    for delay in (0.3, 0.5, 0.7, 0.9):
        echo = _emos("topic", "echo", "/listener/status", "--run", system.run_dir.name)
        time.sleep(delay)
        echo.send_signal(signal.SIGTERM)
        _, err = echo.communicate(timeout=HANG_S)
        # -15: the signal came before Python set up its handler (and before any FIFO existed).
        assert echo.returncode in (143, -signal.SIGTERM) and "Traceback" not in err, err
        assert _fifos(system) == before, delay
