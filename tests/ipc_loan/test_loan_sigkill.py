"""A publisher SIGKILLed while a loaned message is open never leaves a torn message visible
(issue 34, item 2), as for a writer killed mid-copy (tests/runtime/test_transport.py)."""
import os
import signal
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from emos import msgs as M
from emos.transport.context import RunContext
from emos.transport.pubsub import Publisher, Subscriber
from tests.ipc_loan.torn import FORK, sigkill_writer_and_check

pytestmark = [pytest.mark.process, pytest.mark.usefixtures("ring_path")]  # readers loan in C and in Python


def _loaning_writer(run_dir: str, run_id: str, size: int, ready) -> None:
    """Loans frames forever, filling each in chunks (a slow camera), the checksum in its label."""
    ctx = RunContext(run_id, Path(run_dir), owner=False)
    pub = Publisher(ctx, "/stream", M.UInt8MultiArray, publisher_id="writer", depth=4)
    rng = np.random.default_rng(os.getpid())
    ready.set()
    seq = 0
    while True:
        payload = rng.integers(0, 256, size, dtype=np.uint8)
        dim = M.MultiArrayDimension(label=f"{seq}:{zlib.crc32(payload.data)}", size=size, stride=size)
        with pub.loan(M.UInt8MultiArray, shape=(size,), layout=M.MultiArrayLayout(dim=[dim])) as msg:
            for start in range(0, size, 64 * 1024):
                msg.data[start : start + 64 * 1024] = payload[start : start + 64 * 1024]
        seq += 1


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(size=st.sampled_from([1 << 16, 1 << 20, 3 << 20]), kill_after=st.floats(0.0, 0.05))
def test_no_torn_message_when_the_writer_is_sigkilled_mid_loan(ctx, size, kill_after):
    sigkill_writer_and_check(ctx, _loaning_writer, size, kill_after)


def _open_loan_then_wait(run_dir: str, run_id: str, filled) -> None:
    ctx = RunContext(run_id, Path(run_dir), owner=False)
    pub = Publisher(ctx, "/cam", M.Image, publisher_id="cam", depth=2)
    pub.publish(M.Image.from_numpy(np.full((48, 64, 3), 1, np.uint8)))
    with pub.loan(M.Image, shape=(48, 64, 3)) as msg:
        msg.data[: msg.data.size // 2] = 2  # half a frame: then killed
        filled.set()
        time.sleep(120)  # killed long before (a multiprocessing.Event waiter must not die: its set() would hang)


def test_a_writer_killed_with_a_loan_open_leaves_nothing_visible_and_its_restart_carries_on(ctx):
    filled = FORK.Event()
    proc = FORK.Process(target=_open_loan_then_wait, args=(str(ctx.run_dir), ctx.run_id, filled))
    proc.start()
    try:
        assert filled.wait(60)
        sub = Subscriber(ctx, "/cam", M.Image, queue_size=8, transient_local=True)
        os.kill(proc.pid, signal.SIGKILL)
        proc.join()
        got = sub.take()
        assert [int(m.data.max()) for m in got] == [1]  # the message before the loan, whole
        assert sub.latest() is None
        # A restarted publisher (same id) reopens the ring and writes the number the loan held.
        pub = Publisher(ctx, "/cam", M.Image, publisher_id="cam", depth=2)
        with pub.loan(M.Image, shape=(48, 64, 3)) as msg:
            msg.data[:] = 3
        [m] = sub.take()
        assert int(m.data.min()) == int(m.data.max()) == 3
        assert pub.ring.head == 2
        sub.close()
        pub.close()
    finally:
        if proc.is_alive():
            proc.kill()
        proc.join()
