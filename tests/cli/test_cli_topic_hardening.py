"""Issue 31 items 13 and 18: `emos topic pub` checks what it is given; a killed `emos topic echo`
does not leave its wake-up files behind while the run goes on."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import pytest

from tests.runtime.helpers import LISTENER, SystemUnderTest, wait_until

pytestmark = pytest.mark.process



@pytest.fixture(scope="module")
def system(tmp_path_factory):
    s = SystemUnderTest(tmp_path_factory.mktemp("topic_hardening"), LISTENER).wait_up(components=["listener"])
    try:
        yield s
    finally:
        code = s.stop()
        assert code == 0, s.output()
        assert s.leftovers() == []


def emos(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "emos", *args], check=False, capture_output=True, text=True, timeout=timeout)


def start(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "emos", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def segments(system, topic_token: str) -> list[str]:
    return [n for n in os.listdir("/dev/shm") if n.startswith(system.ctx.shm_prefix + topic_token + ".")]


def wake_files(system) -> set[str]:
    """The wake-up FIFOs and state pages of the run, and its subscriber entries (topic/token)."""
    files = {f"wake/{p.name}" for p in (system.run_dir / "wake").iterdir()}
    for folder in (system.run_dir / "subs").iterdir():
        files |= {f"subs/{folder.name}/{p.name}" for p in folder.iterdir()}
    return files


def files_of_new_reader(system, before: set[str], topic_token: str) -> set[str]:
    """Wait until a new reader is fully registered on the topic: FIFO, state page, subscriber entry."""
    def ready():
        new = wake_files(system) - before
        tokens = {name.rsplit("/", 1)[1] for name in new if name.startswith(f"subs/{topic_token}/")}
        for token in tokens:
            mine = {f"wake/{token}", f"wake/{token}.state", f"subs/{topic_token}/{token}"}
            if mine <= new:
                return mine
        return None

    return wait_until(ready, timeout=60, what=f"a new reader of {topic_token}")


def sigkill(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=30)


# ------------------------------------------------------------------------------------- item 13
@pytest.mark.parametrize("option,value,expected", [
    ("--rate", "nan", "--rate must be a finite number, got 'nan'"),
    ("--rate", "inf", "--rate must be a finite number, got 'inf'"),
    ("--rate", "-5", "--rate must be a rate in Hz of at least"),
    ("--rate", "0", "--rate must be a rate in Hz of at least"),
    ("-n", "-1", "--count must be 0 or more (0: until Ctrl-C), got '-1'"),
    ("--count", "two", "--count must be a whole number, got 'two'"),
])
def test_pub_refuses_bad_numbers_at_argument_parsing(system, option, value, expected):
    out = emos("topic", "pub", "/shared", "String", '{"data": "x"}', option, value, "--run", system.run_dir.name)
    assert out.returncode == 2, out.stdout + out.stderr
    assert expected in out.stderr and "Traceback" not in out.stderr
    assert segments(system, "shared") == []


@pytest.mark.parametrize("msg_type,fields,expected", [
    ("Twist", '{"linear": {"x": "fast"}}', "bad FIELDS for geometry_msgs/msg/Twist: field linear.x expects a float, got str 'fast'"),
    ("Int64", '{"data": 1.5}', "bad FIELDS for std_msgs/msg/Int64: field data expects an int"),
    ("Twist", '{"linear": 5}', "field linear expects a message, got int 5"),
    ("Twist", '{"linear": {"q": 1}}', "in field linear: Vector3 has no field 'q'; fields are x, y, z"),
    ("Twist", "[1, 2]", "FIELDS must be a JSON (or YAML) mapping of geometry_msgs/msg/Twist fields (linear, angular)"),
    ("Twist", "{a: [}", "is neither JSON"),
    ("NoSuchType", "{}", "MSG_TYPE: unknown message type 'NoSuchType'"),
])
def test_pub_explains_a_bad_message_in_one_line(system, msg_type, fields, expected):
    out = emos("topic", "pub", "/cmd", msg_type, fields, "--run", system.run_dir.name)
    assert out.returncode == 2, out.stdout + out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("emos topic pub: "), out.stderr
    assert expected in lines[0]
    assert segments(system, "cmd") == []


def test_pub_refuses_a_type_the_topics_readers_do_not_read_when_it_has_no_publisher(system):
    assert segments(system, "shared") == []  # nobody publishes /shared: only the listener's input says its type
    out = emos("topic", "pub", "/shared", "Int64", '{"data": 1}', "--run", system.run_dir.name)
    assert out.returncode == 1, out.stdout + out.stderr
    assert out.stderr.strip() == ("emos topic pub: /shared is read as std_msgs/msg/String by listener; "
                                  "you asked to publish std_msgs/msg/Int64")
    assert segments(system, "shared") == []
    good = emos("topic", "pub", "/shared", "String", '{"data": "hi"}', "-n", "3", "--rate", "50", "--run", system.run_dir.name)
    assert good.returncode == 0 and "published 3 String on /shared" in good.stdout, good.stderr
    assert system.state("listener") == "active"


# ------------------------------------------------------------------------------------- item 18
def test_a_sigkilled_topic_echo_leaves_no_wakeup_files_while_the_run_goes_on(system):
    before = wake_files(system)
    echo = start("topic", "echo", "/listener/status", "--run", system.run_dir.name)
    try:
        mine = files_of_new_reader(system, before, "listener~status")
        # A first message: the echo is registered in the publisher's ring, not only in the
        # topic's subscriber list (a reader killed between the two is left to the sweep, below).
        wait_until(lambda: echo.stdout.readline().strip() != "", timeout=60, what="a first message")
    finally:
        sigkill(echo)
    # The listener publishes its status every step: its next wake-up finds the reader gone.
    wait_until(lambda: not (mine & wake_files(system)), timeout=60, what=f"{sorted(mine)} removed")
    assert system.proc.poll() is None and system.state("listener") == "active"


def test_a_sigkilled_reader_of_a_topic_nobody_publishes_any_more_is_swept_by_the_next_command(system):
    # A topic of its own: the killed publisher's ring stays until the run ends.
    pub = start("topic", "pub", "/other", "String", '{"data": "hi"}', "--rate", "20", "-n", "0", "--run", system.run_dir.name)
    try:
        wait_until(lambda: segments(system, "other"), timeout=60, what="the CLI's ring on /other")
        before = wake_files(system)
        echo = start("topic", "echo", "/other", "--run", system.run_dir.name)
        try:
            mine = files_of_new_reader(system, before, "other")
        finally:
            sigkill(pub)  # first, so no publisher is left to notice the reader's death
            sigkill(echo)
        assert mine <= wake_files(system)
        listing = emos("topic", "list", "--json", "--run", system.run_dir.name)
        assert listing.returncode == 0, listing.stderr
        assert not (mine & wake_files(system))
        assert json.loads(listing.stdout)["/other"]["subscribers"] == 0
        assert system.proc.poll() is None and system.state("listener") == "active"
    finally:
        if pub.poll() is None:
            sigkill(pub)


# Without a system: the rule by which a reader counts as dead (emos/transport/waker.py).
CHILD_READER = """
import sys, time
from pathlib import Path
from emos.transport.context import RunContext
from emos.transport.waker import Waker
ctx = RunContext(sys.argv[1], Path(sys.argv[2]), owner=False)
waker = Waker(ctx)
print(waker.token, flush=True)
time.sleep(600)
"""


@pytest.fixture
def run_ctx():
    from emos.transport.context import RunContext

    ctx = RunContext.create()
    yield ctx
    ctx.remove_everything()


def killed_reader(ctx) -> int:
    """The token of a Waker whose process was SIGKILLed (its files left behind)."""
    child = subprocess.Popen([sys.executable, "-c", CHILD_READER, ctx.run_id, str(ctx.run_dir)], stdout=subprocess.PIPE, text=True)
    try:
        token = int(child.stdout.readline())
    finally:
        child.kill()
        child.communicate(timeout=30)
    return token


def test_sweep_removes_a_killed_readers_files_and_only_those(run_ctx):
    from emos.transport.waker import Waker, fifo_path, state_path, sweep_dead_wakers

    live = Waker(run_ctx)
    try:
        dead = killed_reader(run_ctx)
        (run_ctx.subscriber_dir("/t") / f"{dead:016x}").touch(mode=0o600)
        (run_ctx.subscriber_dir("/t") / f"{live.token:016x}").touch(mode=0o600)
        assert fifo_path(run_ctx, dead).exists() and state_path(run_ctx, dead).exists()
        assert sweep_dead_wakers(run_ctx) == 1
        assert not fifo_path(run_ctx, dead).exists() and not state_path(run_ctx, dead).exists()
        assert not (run_ctx.run_dir / "subs" / "t" / f"{dead:016x}").exists()
        assert fifo_path(run_ctx, live.token).exists() and state_path(run_ctx, live.token).exists()
        assert (run_ctx.run_dir / "subs" / "t" / f"{live.token:016x}").exists()
        assert sweep_dead_wakers(run_ctx) == 0
    finally:
        live.close()


def test_a_reused_pid_does_not_keep_a_dead_readers_files_and_a_live_owner_does(run_ctx):
    import struct

    from emos.transport.context import make_run_id
    from emos.transport.waker import fifo_path, remove_if_dead, state_path

    ours = int(make_run_id().split("-")[1])
    dead = killed_reader(run_ctx)
    page = state_path(run_ctx, dead)
    with open(page, "r+b") as f:  # as if the dead reader's pid now belonged to this (live) process
        f.seek(8)
        f.write(struct.pack("=QQ", os.getpid(), ours))
    assert remove_if_dead(run_ctx, dead) is False  # the owner runs: it may be closing or still opening
    assert fifo_path(run_ctx, dead).exists()
    with open(page, "r+b") as f:  # same pid, another start time: a reused pid, not the owner
        f.seek(8)
        f.write(struct.pack("=QQ", os.getpid(), ours - 1))
    assert remove_if_dead(run_ctx, dead) is True
    assert not fifo_path(run_ctx, dead).exists() and not page.exists()
