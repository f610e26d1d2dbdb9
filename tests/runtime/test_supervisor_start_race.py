"""A group that escalates while one of its children is still starting leaves no second copy of it.

The race (seen in runs): in a one_for_one group, a restart of ``slow`` waits for its new process
to come up when a sibling's crash breaks the group's restart intensity. The escalation stopped
only the children already running, so the process still starting survived next to the copy
the root started when it restarted the group; both waited on the same hello and drove the same
control socket. Here the test holds ``slow``'s start-up on a file it controls, so the escalation
always happens while that start is in progress: no timing is involved.
"""
from __future__ import annotations

import asyncio
import logging
import os
import signal
import tempfile
from pathlib import Path

import psutil
import pytest

from emos import BaseComponent
from emos.core.rpc import AsyncRpcClient, RpcServer
from emos.supervisor.system import Package, System
from tests.runtime.helpers import SystemUnderTest, wait_until

pytestmark = pytest.mark.process

RECIPE = """
BLOCK, WAITING = {block!r}, {waiting!r}
PHASE = {phase!r}


def hold_while_blocked():
    '''Start-up waits here while the test's BLOCK file exists; WAITING/<pid> says who waits.'''
    if not os.path.exists(BLOCK):
        return
    open(os.path.join(WAITING, str(os.getpid())), "w").close()
    end = time.monotonic() + 600  # bounds a hang only: the test removes BLOCK
    while os.path.exists(BLOCK) and time.monotonic() < end:
        time.sleep(0.01)


class Slow(BaseComponent):
    @property
    def _wake_spin_us(self):
        # The Node reads this in the worker process before it says hello to the supervisor:
        # the one place component code runs that early.
        if PHASE == "before_hello":
            hold_while_blocked()
        return None

    def custom_on_configure(self):
        if PHASE == "configure":  # after the hello, while the supervisor drives the lifecycle
            hold_while_blocked()

    def _execution_step(self):
        self.health_status.set_healthy()


class Steady(BaseComponent):
    def _execution_step(self):
        self.health_status.set_healthy()


slow, crashy = Slow(component_name="slow"), Steady(component_name="crashy")
for c in (slow, crashy):
    c.config.loop_rate = 20.0
launcher = Launcher(multi_processing=True, max_restarts=5, max_seconds=600)
# One restart in the group is allowed, the second escalates to the root (which allows five).
launcher.add_pkg(components=[slow, crashy], package_name="g", max_restarts=1, max_seconds=600)
launcher.bringup()
"""


def _live(system: SystemUnderTest, name: str) -> set[int]:
    """Pids of the live (not zombie) processes of component ``name`` in this run: the launcher's
    descendants (it is their subreaper) named ``emos:<name>``. Forked workers do not show the
    run id in /proc/<pid>/environ (it was set after the launcher's exec), so go by ancestry."""
    pids = set()
    for p in psutil.Process(system.proc.pid).children(recursive=True):
        try:
            if p.name() == f"emos:{name}" and p.status() != psutil.STATUS_ZOMBIE:
                pids.add(p.pid)
        except psutil.Error:
            pass
    return pids


def _alive(pid: int) -> bool:
    """Whether component process ``pid`` still runs (by name: a recycled pid is someone else's)."""
    try:
        p = psutil.Process(pid)
        return p.name().startswith("emos:") and p.status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


@pytest.mark.parametrize("phase", ["before_hello", "configure"])
def test_escalation_while_a_child_is_starting_leaves_exactly_one_copy_of_it(tmp_path, phase):
    block, waiting = tmp_path / "block", tmp_path / "waiting"
    waiting.mkdir()
    system = SystemUnderTest(tmp_path, RECIPE.format(block=str(block), waiting=str(waiting), phase=phase))
    stray: set[int] = set()
    try:
        system.wait_up(components=["slow", "crashy"])
        first = system.pid("slow")

        # 1. slow is killed and its restart (restart 1 of 1 allowed) holds in start-up.
        block.touch()
        os.kill(first, signal.SIGKILL)
        starting = int(wait_until(lambda: next(iter(os.listdir(waiting)), None), what="slow's restart to wait in start-up"))
        stray.add(starting)
        assert starting != first

        # 2. The sibling's crash is restart 2: the group escalates while slow is still starting,
        #    and the root starts the group again, whose new slow holds in start-up as well.
        os.kill(system.pid("crashy"), signal.SIGKILL)
        second = int(wait_until(lambda: next((n for n in os.listdir(waiting) if int(n) != starting), None),
                                what="the restarted group's slow to wait in start-up"))
        stray.add(second)
        # The escalation ended the start in progress: its process is gone before the new copy exists.
        assert not _alive(starting), f"slow pid {starting} (started before the escalation) still runs next to pid {second}"

        # 3. Let start-up go on: one copy of each component, the one the supervisor tracks.
        block.unlink()
        wait_until(lambda: system.state("slow") == "active" and system.state("crashy") == "active", what="slow and crashy active")
        tracked = {n: system.pid(n) for n in ("slow", "crashy")}
        assert tracked["slow"] == second
        assert _live(system, "slow") == {tracked["slow"]}
        assert _live(system, "crashy") == {tracked["crashy"]}
        stray |= _live(system, "slow") | _live(system, "crashy")
        events = system.events()
        assert [e["supervisor"] for e in events if e["event"] == "escalated"] == ["g"]
        assert [e for e in events if e["event"] == "start_failed"] == []
        assert "ignoring a hello" not in system.output()  # no killed copy lived long enough to say hello
    finally:
        if block.exists():
            block.unlink()  # a copy held in start-up (old code) must not outlive the test
        code = system.stop()
        survivors = sorted(pid for pid in stray if _alive(pid))
        for pid in survivors:  # only if the launcher could not end them (the bug this test is about)
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    assert code == 0, system.output()
    assert survivors == [], f"component processes outlived the run: {survivors}"
    assert system.leftovers() == []


def test_stopping_the_run_while_a_restart_waits_in_start_up_ends_that_process_too(tmp_path):
    """A stop cancels a start in progress (it does not wait for it to come up or time out)."""
    block, waiting = tmp_path / "block", tmp_path / "waiting"
    waiting.mkdir()
    system = SystemUnderTest(tmp_path, RECIPE.format(block=str(block), waiting=str(waiting), phase="before_hello"))
    starting = None
    try:
        system.wait_up(components=["slow", "crashy"])
        block.touch()
        os.kill(system.pid("slow"), signal.SIGKILL)
        starting = int(wait_until(lambda: next(iter(os.listdir(waiting)), None), what="slow's restart to wait in start-up"))
        code = system.stop()  # BLOCK still exists: only the stop can end that start
        assert code == 0, system.output()
        assert not _alive(starting), f"slow pid {starting}, held in start-up, outlived the run"
    finally:
        if block.exists():
            block.unlink()
        system.stop()
        if starting is not None and _alive(starting):
            os.kill(starting, signal.SIGKILL)
    assert "start of slow abandoned" in system.output()
    assert system.leftovers() == []


class _Idle(BaseComponent):
    def _execution_step(self):
        self.health_status.set_healthy()


def test_a_hello_completes_only_the_start_of_the_process_that_sent_it(caplog):
    """Through the real control socket: a hello from another pid of the same component (a
    stale incarnation) is ignored with a log line naming both; the right pid's hello completes it."""
    system = System([Package(components=[_Idle(component_name="idle")], multiprocessing=True)])
    with tempfile.TemporaryDirectory(prefix="emos-hello-") as d:  # short: AF_UNIX paths are limited
        path = Path(d) / "s.sock"

        async def main() -> None:
            server = RpcServer(path, system._control_ops(), name="supervisor")
            await server.start()
            client = AsyncRpcClient(path)
            try:
                fut = system.expect_hello("idle", pid=4242)
                assert await client.call("hello", component="idle", pid=4243) is True
                assert await client.call("hello", component="other", pid=4242) is True
                assert not fut.done()
                with pytest.raises(Exception, match="'pid' must be an int"):
                    await client.call("hello", component="idle", pid="4242")
                assert not fut.done()
                assert await client.call("hello", component="idle", pid=4242) is True
                assert await asyncio.wait_for(fut, 10.0) == 4242
                # Said twice: the second is stale (nothing waits for it any more) and harmless.
                assert await client.call("hello", component="idle", pid=4242) is True
            finally:
                await client.close()
                await server.close()

        with caplog.at_level(logging.WARNING, logger="emos.supervisor"):
            asyncio.run(main())
    lines = [r.getMessage() for r in caplog.records if "ignoring a hello" in r.getMessage()]
    assert any("'idle' pid 4243" in line for line in lines), lines
    assert any("'other' pid 4242" in line for line in lines), lines
    assert any("'idle' pid 4242" in line for line in lines), lines
