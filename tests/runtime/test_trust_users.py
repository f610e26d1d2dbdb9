"""Another local user attacks our runs through /dev/shm and /tmp (issue 9, transport half).

Each attack is run as a real second user (created for the module, removed after). Names are
planted only in the namespace of this test's own run (or in a private stand-in for /dev/shm and
/tmp), never under a generic run id, so other people's runs on this machine are not disturbed.
"""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from emos import msgs as M
from emos.transport import context
from emos.transport.context import SHM_DIR, RunContext, RuntimeDirError
from emos.transport.pubsub import Publisher, Subscriber
from emos.transport.waker import Waker
from tests.runtime.helpers import HANG_S, SystemUnderTest
from tests.runtime.trust_helpers import (  # noqa: F401 - the fixtures are imported to register them here
    attacker_fixture,
    forged_ring,
    planted_fixture,
    publish_bad_message,
    shared_tmp_fixture,
    write_own_file,
)

pytestmark = pytest.mark.process


def _seg(ctx, topic, pub, gen=0):
    return SHM_DIR / ctx.segment_name(topic, pub, gen)


def test_rings_another_user_planted_in_our_run_are_never_read(ctx, planted, caplog):
    topic = "/camera/rgb"
    pub = Publisher(ctx, topic, M.String, publisher_id="cam")
    waker = Waker(ctx)
    sub = Subscriber(ctx, topic, M.String, waker=waker)
    try:
        forged = forged_ring(ctx, M.String, [M.String(data="forged")] * 3)
        planted.plant_file(_seg(ctx, topic, "evil"), forged, mode=0o666)
        # A higher generation under the genuine publisher's name must not hide its real ring.
        planted.plant_file(_seg(ctx, topic, "cam", 7), forged, mode=0o666)
        # A directory and a link to a ring of ours must neither raise nor be followed.
        planted.plant_dir(_seg(ctx, topic, "dir"))
        planted.plant_symlink(_seg(ctx, topic, "link"), SHM_DIR / pub.segment)
        pub.publish(M.String(data="genuine"))
        sub.rescan(force=True)
        assert [m.data for m in sub.take()] == ["genuine"]
        assert sub.publishers() == ["cam"]
        pub.publish(M.String(data="again"))
        assert sub.latest().data == "again"
        assert f"is owned by uid {planted.uid}" in caplog.text and "camera~rgb.evil.g0" in caplog.text
    finally:
        sub.close()
        waker.close()
        pub.close()


def test_a_restarted_publisher_skips_generation_names_another_user_took(ctx, planted):
    topic = "/scan"
    forged = forged_ring(ctx, M.String, [M.String(data="forged")])
    planted.plant_file(_seg(ctx, topic, "lidar", 0), forged, mode=0o600)
    planted.plant_dir(_seg(ctx, topic, "lidar", 1))
    sub = Subscriber(ctx, topic, M.String)
    pub = Publisher(ctx, topic, M.String, publisher_id="lidar")
    try:
        assert pub.ring.generation == 2
        pub.publish(M.String(data="real"))
        assert [m.data for m in sub.take()] == ["real"]
    finally:
        sub.close()
        pub.close()


def test_exit_cleanup_removes_everything_of_ours_past_what_another_user_planted(planted):
    ctx = RunContext.create()
    pub = Publisher(ctx, "/a", M.Int64, publisher_id="x")
    pub.close()
    ours = SHM_DIR / pub.ring.name if pub.ring else _seg(ctx, "/a", "x")
    planted.plant_dir(SHM_DIR / f"{ctx.shm_prefix}a.planted-dir.g0")
    planted.plant_file(SHM_DIR / f"{ctx.shm_prefix}a.planted-file.g0", b"x", mode=0o666)
    write_own_file(SHM_DIR / f"{ctx.shm_prefix}b.z.g0", b"ours")
    assert ctx.remove_everything() == 2
    assert not ours.exists() and not (SHM_DIR / f"{ctx.shm_prefix}b.z.g0").exists()
    assert not ctx.run_dir.exists()
    assert (SHM_DIR / f"{ctx.shm_prefix}a.planted-dir.g0").is_dir()  # not ours to remove


def _dead_run_id() -> str:
    proc = subprocess.Popen(["sleep", "30"])
    try:
        return context.make_run_id(proc.pid)
    finally:
        proc.kill()
        proc.wait()


def test_the_stale_sweep_skips_what_other_users_planted(planted, shared_tmp, monkeypatch):
    # shared_tmp stands in for /dev/shm here: a dead run id planted in the real one would make
    # every other run on this machine (without this fix) fail at start-up.
    monkeypatch.setattr(context, "SHM_DIR", shared_tmp)
    dead = _dead_run_id()
    ours = write_own_file(shared_tmp / f"emos.{dead}.t.p.g0", b"stale")
    their_dir = planted.plant_dir(shared_tmp / f"emos.{dead}.x")
    their_file = planted.plant_file(shared_tmp / f"emos.{dead}.y", b"theirs", mode=0o644)
    generic = planted.plant_dir(shared_tmp / "emos.1-1.x")
    assert dead in context.sweep_stale_runs()
    assert not ours.exists()
    assert their_dir.is_dir() and their_file.exists() and generic.is_dir()
    ctx = RunContext.create()  # what `emos run` does first: must not fail either
    ctx.remove_everything()


def test_a_runtime_directory_another_user_controls_is_refused_with_a_clear_error(planted, shared_tmp, monkeypatch):
    monkeypatch.setattr(context, "TMP_DIR", shared_tmp)
    monkeypatch.delenv("XDG_RUNTIME_DIR", raising=False)
    monkeypatch.delenv(context.ENV_RUNTIME_DIR, raising=False)
    ours = shared_tmp / "looks-like-ours"
    ours.mkdir(mode=0o700)
    root = shared_tmp / f"emos-{os.geteuid()}"
    # A link to a directory of ours, mode 0700: following it would pass an owner check.
    planted.plant_symlink(root, ours)
    with pytest.raises(RuntimeDirError, match="is a symbolic link.*EMOS_RUNTIME_DIR"):
        context.runtime_root()
    root.unlink()
    planted.plant_dir(root)
    with pytest.raises(RuntimeDirError, match=f"is owned by uid {planted.uid}"):
        context.runtime_root()
    monkeypatch.setenv(context.ENV_RUNTIME_DIR, str(shared_tmp / "mine"))
    assert context.runtime_root() == shared_tmp / "mine"
    assert (os.stat(shared_tmp / "mine").st_mode & 0o777) == 0o700


def _cli(*args: str, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "emos.tools.cli", *args], env=env, capture_output=True,
                          text=True, timeout=120)


def test_an_xdg_runtime_dir_another_user_owns_is_refused_in_one_line(planted, shared_tmp, monkeypatch):
    # `sudo -E` and `su` keep the invoking user's XDG_RUNTIME_DIR: its owner could rename our
    # `emos` folder in it mid-run (restarts then failed and the run gave up).
    theirs = planted.plant_dir(shared_tmp / "run-user-theirs")
    monkeypatch.delenv(context.ENV_RUNTIME_DIR, raising=False)
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(theirs))
    with pytest.raises(RuntimeDirError, match=f"XDG_RUNTIME_DIR={theirs}.*owned by uid {planted.uid}.*unset XDG_RUNTIME_DIR"):
        context.runtime_root()
    assert not (theirs / "emos").exists()
    # The command line says it in one line, without a traceback around it.
    env = {k: v for k, v in os.environ.items() if k != context.ENV_RUNTIME_DIR}
    env["XDG_RUNTIME_DIR"] = str(theirs)
    for args in (("status",), ("run", "--duration", "1", str(Path(__file__).parents[2] / "recipes" / "sensor_demo.py"))):
        out = _cli(*args, env=env)
        assert out.returncode == 1, out
        assert "Traceback" not in out.stderr and out.stderr.strip().count("\n") == 0, out.stderr
        assert out.stderr.startswith("emos: the EMOS runtime directory") and "XDG_RUNTIME_DIR" in out.stderr


def test_a_runtime_directory_under_a_parent_others_can_write_is_refused(planted, shared_tmp, monkeypatch):
    monkeypatch.delenv("XDG_RUNTIME_DIR", raising=False)
    open_parent = shared_tmp / "open"
    open_parent.mkdir()
    os.chmod(open_parent, 0o777)  # writable by all, not sticky: anyone may rename what is in it
    monkeypatch.setenv(context.ENV_RUNTIME_DIR, str(open_parent / "emos"))
    with pytest.raises(RuntimeDirError, match=r"its parent .*open is writable by other users \(mode 0o777\) without the sticky bit"):
        context.runtime_root()
    os.chmod(open_parent, 0o1777)  # sticky, as /tmp: only the owner of an entry may rename it
    assert context.runtime_root() == open_parent / "emos"
    # A link of ours to a directory another user owns is judged by where it leads.
    link = shared_tmp / "link"
    link.symlink_to(planted.plant_dir(shared_tmp / "their-dir"))
    monkeypatch.setenv(context.ENV_RUNTIME_DIR, str(link / "emos"))
    with pytest.raises(RuntimeDirError, match=f"their-dir is owned by uid {planted.uid}"):
        context.runtime_root()


STATUS_RECIPE = """
class Steady(BaseComponent):
    def _execution_step(self):
        self.health_status.set_healthy()

w = Steady(component_name="w")
w.config.loop_rate = 50
launcher = Launcher(multi_processing=True, heartbeat_timeout=0.5)
launcher.add_pkg(components=[w])
launcher.bringup()
"""


def test_forged_status_rings_neither_stop_hang_detection_nor_emos_status(tmp_path, planted):
    system = SystemUnderTest(tmp_path, STATUS_RECIPE).wait_up(components=["w"])
    try:
        ctx = system.ctx
        bad = forged_ring(ctx, M.ComponentStatus, [M.ComponentStatus()] * 3, bad_slot=True)
        planted.plant_file(_seg(ctx, "/w/status", "evil"), bad, mode=0o666)  # another user
        crashed = _seg(ctx, "/w/status", "crashed")  # one of ours, as a crashed writer leaves it
        planted.planted.append(crashed)
        write_own_file(crashed, bad)
        time.sleep(1.5)  # the heartbeat reader rescans at least every second
        publish_bad_message(crashed)  # it is read only once it has news
        time.sleep(0.5)
        status = subprocess.run([sys.executable, "-m", "emos", "status", "--run", ctx.run_id, "--json"], capture_output=True, text=True, timeout=60)
        assert status.returncode == 0, status.stderr
        assert "w" in json.dumps(json.loads(status.stdout))
        pid = system.pid("w")
        os.kill(pid, signal.SIGSTOP)  # a hang: only the heartbeat can tell
        new = system.wait_new_pid("w", pid, timeout=HANG_S)
        assert new != pid
        assert any(e["event"] == "exit" and e["child"] == "w" and e["reason"] == "hang" for e in system.events())
        assert not psutil.pid_exists(pid) or psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    finally:
        assert system.stop() == 0
    # The run removed all of its own state; what the other user planted stays where it was.
    assert [p for p in system.leftovers() if "evil" not in p] == []
    out = system.output()
    assert "w~status.evil.g0" in out and "w~status.crashed.g0" in out, out
