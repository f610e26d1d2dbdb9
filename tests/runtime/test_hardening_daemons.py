"""Issue 31, item 7: a daemon a component starts (double fork, setsid, environment cleared, every
file descriptor closed) dies with the component incarnation that started it, however that
incarnation ends: a crash, a restart, SIGKILL, or the end of the run.

Each daemon execs a Python that sleeps forever with the test's marker in its argv, after writing
``<dir>/<time>-<pid>``; the tests count the live processes whose argv holds the marker.
"""
import os
import signal
import time
import uuid

import psutil
import pytest

from tests.runtime.helpers import HANG_S, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

# argv: marker, pid folder. Double fork with setsid between, as daemon(3) does.
DAEMON = r"""
import os, sys, time
marker, folder = sys.argv[1], sys.argv[2]
if os.fork():
    os._exit(0)
os.setsid()
if os.fork():
    os._exit(0)
with open(os.path.join(folder, f"{time.time():.6f}-{os.getpid()}"), "w") as f:
    f.write(marker)
os.closerange(0, 4096)
os.execve(sys.executable, [sys.executable, "-c", "import time\nwhile True: time.sleep(3600)", marker], {})
"""

SPAWNER = f"""
import subprocess

DAEMON = {DAEMON!r}

class Spawner(BaseComponent):
    '''Starts one daemon when activated; MODE crash: os._exit in a step, raise: an exception in
    every step (a COMPONENT_FAILURE: the default fallback restarts it), steady: stays healthy.'''
    def custom_on_activate(self):
        subprocess.run([sys.executable, "-c", DAEMON, os.environ["DAEMON_MARKER"], os.environ["DAEMON_DIR"]], check=True)
        self.t0 = time.monotonic()
    def _execution_step(self):
        mode = os.environ["MODE"]
        if mode != "steady" and time.monotonic() - self.t0 > 0.3:
            if mode == "crash":
                os._exit(3)
            raise RuntimeError("broken on purpose")
        self.health_status.set_healthy()
"""


def _daemons(folder) -> list[int]:
    """Pids of the daemons started so far, oldest first."""
    return [int(p.name.split("-")[1]) for p in sorted(folder.iterdir(), key=lambda p: float(p.name.split("-")[0]))]


def _alive_with(marker: str) -> list[int]:
    out = []
    for p in psutil.process_iter(["cmdline"]):
        try:
            if marker in (p.info["cmdline"] or []) and p.status() != psutil.STATUS_ZOMBIE:
                out.append(p.pid)
        except psutil.Error:
            continue
    return out


def _only_the_daemon(marker: str) -> list[int]:
    """Waits until one process carries the marker, and returns it. The daemon writes its pid file
    before the double fork's middle process has exited (it carries the marker too, and a loaded
    machine can leave it unscheduled for a while): that one goes by itself. Two daemons would not."""
    return wait_until(lambda: (alive := _alive_with(marker)) and len(alive) == 1 and alive, timeout=HANG_S,
                      what="exactly one process with the daemon's marker")


def _alive(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


def _start(tmp_path, mode: str, multi: bool = True, with_thread: bool = False) -> tuple[SystemUnderTest, str, object]:
    """``with_thread``: a second group runs a component as a thread of the launcher (a mixed run)."""
    marker = f"emos-test-daemon-{uuid.uuid4().hex}"
    folder = tmp_path / "daemons"
    folder.mkdir()
    thread_group = "launcher.add_pkg(components=[BaseComponent(component_name='threaded')], multiprocessing=False)" if with_thread else ""
    system = SystemUnderTest(tmp_path, SPAWNER + f"""
c = Spawner(component_name="spawner")
c.config.loop_rate = 20.0
launcher = Launcher(multi_processing={multi}, max_restarts=100, max_seconds=1.0)
launcher.add_pkg(components=[c])
{thread_group}
launcher.bringup()
""", env={"DAEMON_MARKER": marker, "DAEMON_DIR": str(folder), "MODE": mode}).wait_up()
    return system, marker, folder


@pytest.mark.parametrize("mode", ["crash", "raise"])
def test_no_daemon_outlives_its_crashed_incarnation_in_a_crash_loop(tmp_path, mode):
    system, marker, folder = _start(tmp_path, mode)
    try:
        daemons = wait_until(lambda: len(_daemons(folder)) >= 5 and _daemons(folder), timeout=60, what="5 incarnations and their daemons")
        # Every incarnation but the newest has ended: each of their daemons must be gone (the
        # newest one's may still run, or be going with its incarnation).
        wait_until(lambda: not any(_alive(p) for p in daemons[:-1]), timeout=HANG_S, what=f"the daemons of ended incarnations {daemons[:-1]} to die")
        assert len(_alive_with(marker)) <= 2, _alive_with(marker)
    finally:
        assert system.stop() == 0, system.output()[-3000:]
    wait_until(lambda: not _alive_with(marker), timeout=HANG_S, what="no daemon left after the run")
    assert system.leftovers() == []


@pytest.mark.parametrize("with_thread", [False, True], ids=["processes", "mixed"])
def test_the_daemon_of_a_sigkilled_component_dies_and_the_run_leaves_none(tmp_path, with_thread):
    system, marker, folder = _start(tmp_path, "steady", with_thread=with_thread)
    try:
        first = wait_until(lambda: _daemons(folder), timeout=HANG_S, what="the first daemon")
        assert _alive(first[0])
        if with_thread:
            # In a run with threaded components the launcher knows a daemon that left its
            # worker's session only from its sweeps (five a second) of each worker's children.
            time.sleep(1.0)
        # The daemon starts inside the activation; the supervisor's tree lists the incarnation
        # (and its pid) only once the activation has returned.
        old = wait_until(lambda: system.state("spawner") == "active" and system.pid("spawner"), timeout=HANG_S, what="the spawner active")
        os.kill(old, signal.SIGKILL)  # no clean-up in the worker: the supervisor must do it
        system.wait_new_pid("spawner", old, timeout=HANG_S)
        wait_until(lambda: not _alive(first[0]), timeout=HANG_S, what="the SIGKILLed incarnation's daemon to die")
        second = wait_until(lambda: len(_daemons(folder)) == 2 and _daemons(folder)[1], timeout=HANG_S, what="the new incarnation's daemon")
        assert _alive(second) and _only_the_daemon(marker) == [second]
    finally:
        assert system.stop() == 0, system.output()[-3000:]
    wait_until(lambda: not _alive_with(marker), timeout=HANG_S, what="no daemon left after the run")
    assert system.leftovers() == []


def test_the_daemon_of_a_threaded_component_dies_with_the_run(tmp_path):
    system, marker, folder = _start(tmp_path, "steady", multi=False)
    try:
        wait_until(lambda: _daemons(folder), timeout=HANG_S, what="the daemon")
        assert len(_only_the_daemon(marker)) == 1
    finally:
        assert system.stop() == 0, system.output()[-3000:]
    wait_until(lambda: not _alive_with(marker), timeout=HANG_S, what="no daemon left after the run")


def test_the_daemon_dies_when_the_launcher_is_sigkilled(tmp_path):
    system, marker, folder = _start(tmp_path, "steady")
    wait_until(lambda: _daemons(folder), timeout=HANG_S, what="the daemon")
    assert len(_only_the_daemon(marker)) == 1
    system.kill_all()  # the worker gets SIGTERM (parent-death signal) and ends what is below it
    wait_until(lambda: not _alive_with(marker), timeout=HANG_S, what="no daemon left after the launcher's death")


def _zombie_or_alive(pid: int) -> bool:
    try:
        psutil.Process(pid)
        return True
    except psutil.NoSuchProcess:
        return False


def test_a_live_worker_reaps_the_orphans_it_adopted_but_never_its_own_children(tmp_path):
    """A worker is the subreaper of its tree: it must reap an orphan it adopted once that ends
    (no zombie piles up under a long-lived component), and must not take the exit status of a
    child it started itself (``Popen.wait`` after the child ended still gets the real code)."""
    out = tmp_path / "out"
    out.mkdir()
    system = SystemUnderTest(tmp_path, f"""
import subprocess

OUT = {str(out)!r}

class Parent(BaseComponent):
    def custom_on_activate(self):
        # sh outlives its background job's start by 1.5 s, then exits: the job is adopted.
        subprocess.run(["sh", "-c", f"sleep 3 & echo $! > {{OUT}}/orphan; sleep 1.5"], check=True)
        own = subprocess.Popen(["sh", "-c", "exit 7"])
        time.sleep(2.0)  # ended long before we ask: a subreaper that reaped it would have made this 0
        with open(f"{{OUT}}/own", "w") as f:
            f.write(str(own.wait()))
    def _execution_step(self):
        self.health_status.set_healthy()

launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[Parent(component_name="parent")])
launcher.bringup()
""").wait_up()
    try:
        orphan = int(wait_until(lambda: (out / "orphan").exists() and (out / "orphan").read_text().strip(), timeout=HANG_S, what="the orphan's pid"))
        wait_until(lambda: (out / "own").exists() and (out / "own").read_text(), timeout=HANG_S, what="the own child's exit code")
        assert (out / "own").read_text() == "7"
        # The tree lists the incarnation's pid once its activation (which wrote "own") returned.
        worker = wait_until(lambda: system.state("parent") == "active" and system.pid("parent"), timeout=HANG_S, what="the parent active")
        wait_until(lambda: not _zombie_or_alive(orphan), timeout=HANG_S, what=f"the adopted orphan {orphan} to end and be reaped")
        assert system.pid("parent") == worker
        assert not [c for c in psutil.Process(worker).children() if c.status() == psutil.STATUS_ZOMBIE]
    finally:
        assert system.stop() == 0
    assert system.leftovers() == []
