"""Two runs (separate run ids) that share nothing but Zenoh on loopback: a latched map reaches
a subscriber that starts after it was published, and again after that subscriber is killed;
a Monitor of one run reacts to a component status and to a marked topic of the other."""
import json
import os
import signal
import uuid

import pytest

from tests.runtime.helpers import SystemUnderTest, wait_until
from tests.runtime.test_zenoh_net import _config, _free_port

pytestmark = pytest.mark.process

zenoh = pytest.importorskip("zenoh", reason="the 'net' extra (eclipse-zenoh) is not installed")

MAPPER = """
from emos.config import QoSConfig, TRANSIENT_LOCAL

class Mapper(BaseComponent):
    def custom_on_activate(self):
        self.sent = False
    def _execution_step(self):
        if not self.sent:  # once: only the publisher's cache can give it to a later subscriber
            grid = M.OccupancyGrid(data=(np.arange(60 * 40) % 101).astype(np.int8))
            grid.info.width, grid.info.height, grid.info.resolution = 60, 40, 0.05
            grid.header.frame_id = "map-from-A"
            self.publish(self.out_topics[0], grid)
            self.sent = True
            open("published", "w").close()
        self.health_status.set_healthy()

mapper = Mapper(component_name="mapper", outputs=[Topic(name="map", msg_type="OccupancyGrid", qos_profile=QoSConfig(durability=TRANSIENT_LOCAL))])
mapper.config.loop_rate = 5
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[mapper])
launcher.bringup()
"""

READER = """
import json
from emos.config import QoSConfig, TRANSIENT_LOCAL

class Reader(BaseComponent):
    def _execution_step(self):
        grid = self.node.latest("map")
        if grid is not None:
            ok = grid.info.width == 60 and grid.data.tolist() == [i % 101 for i in range(60 * 40)]
            with open("got.json.tmp", "w") as f:
                json.dump({"pid": os.getpid(), "frame_id": grid.header.frame_id, "ok": ok}, f)
            os.replace("got.json.tmp", "got.json")
        self.health_status.set_healthy()

reader = Reader(component_name="reader", inputs=[Topic(name="map", msg_type="OccupancyGrid", qos_profile=QoSConfig(durability=TRANSIENT_LOCAL))])
reader.config.loop_rate = 10
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[reader])
launcher.bringup()
"""


def _read_json(path):
    try:
        return json.loads(path.read_text())
    except (FileNotFoundError, ValueError):
        return None


def _pair(tmp_path, group: str) -> tuple[dict, dict]:
    """Environments of two runs that reach each other over Zenoh on loopback only."""
    end_a, end_b = f"127.0.0.1:{_free_port()}", f"127.0.0.1:{_free_port()}"
    env = {"EMOS_NET_GROUP": group}
    return ({**env, "EMOS_ZENOH_CONFIG": _config(tmp_path / "a.json5", end_a, end_b)},
            {**env, "EMOS_ZENOH_CONFIG": _config(tmp_path / "b.json5", end_b, end_a)})


def test_a_latched_map_reaches_a_subscriber_run_started_after_it_and_again_after_a_restart(tmp_path):
    env_a, env_b = _pair(tmp_path, f"t{uuid.uuid4().hex[:10]}")
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    mapper = SystemUnderTest(a, MAPPER, env={**env_a, "EMOS_NET_TOPICS": "/map"}).wait_up(components=["mapper"], timeout=60)
    reader = None
    try:
        wait_until(lambda: (a / "published").exists(), timeout=30, what="run A to publish its map")
        reader = SystemUnderTest(b, READER, env={**env_b, "EMOS_NET_TOPICS": "/map"}).wait_up(components=["reader"], timeout=60)
        assert reader.ctx.run_id != mapper.ctx.run_id
        got = wait_until(lambda: _read_json(b / "got.json"), timeout=60, what="the latched map in the later run")
        assert got["frame_id"] == "map-from-A" and got["ok"] is True
        assert not [n for n in os.listdir("/dev/shm") if n.startswith(reader.ctx.shm_prefix) and ".map." in n]  # Zenoh only

        # Kill the reader's process: the supervisor restarts it, and the new process asks again.
        first = reader.pid("reader")
        os.kill(first, signal.SIGKILL)
        reader.wait_new_pid("reader", first, timeout=60)
        again = wait_until(lambda: (lambda g: g if g and g["pid"] != first else None)(_read_json(b / "got.json")),
                           timeout=60, what="the map in the restarted reader")
        assert again["frame_id"] == "map-from-A" and again["ok"] is True
        assert (a / "published").exists() and mapper.state("mapper") == "active"
    finally:
        if reader is not None:
            assert reader.stop() == 0
        assert mapper.stop() == 0
    assert reader.leftovers() == [] and mapper.leftovers() == []


WORKER = """
alarm = Topic(name="alarm", msg_type="Int32", transport="zenoh")  # marked for the network

class Worker(BaseComponent):
    def custom_on_activate(self):
        self.n = 0
    def _execution_step(self):
        self.n += 1
        self.publish(alarm, M.Int32(data=self.n))
        if os.path.exists("fail"):
            self.health_status.set_fail_algorithm(algorithm_names=["planner"], message="no path")
        else:
            self.health_status.set_healthy()

worker = Worker(component_name="worker", outputs=[alarm])
worker.config.loop_rate = 5
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[worker])
launcher.bringup()
"""

WATCHER = """
from emos import Event, Action

class Idle(BaseComponent):
    def _execution_step(self):
        self.health_status.set_healthy()

def mark(name, value):
    with open(name, "a") as f:
        f.write(f"{value}\\n")

worker_status = Topic(name="worker/status", msg_type="ComponentStatus")  # a component of run A
alarm = Topic(name="alarm", msg_type="Int32")  # --net-topics all: over Zenoh
idle = Idle(component_name="idle")
idle.config.loop_rate = 2
failed = Event(worker_status.msg.status == M.ComponentStatus.STATUS_FAILURE_ALGORITHM_LEVEL, handle_once=True)
alarmed = Event(alarm.msg.data >= 3, handle_once=True)
local = Event(idle.status_topic.msg.lifecycle_state == "active", handle_once=True)  # this run's: from its ring
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[idle], events_actions={
    failed: Action(mark, args=("failed.txt", worker_status.msg.message)),
    alarmed: Action(mark, args=("alarm.txt", alarm.msg.data)),
    local: Action(mark, args=("local.txt", idle.status_topic.msg.lifecycle_state)),
})
launcher.bringup()
"""


def test_a_monitor_reacts_to_the_status_and_a_topic_of_a_component_of_another_run(tmp_path):
    env_a, env_b = _pair(tmp_path, f"t{uuid.uuid4().hex[:10]}")
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    watcher = SystemUnderTest(b, WATCHER, env={**env_b, "EMOS_NET_TOPICS": "all"}).wait_up(components=["idle", "emos_monitor"], timeout=60)
    worker = None
    try:
        worker = SystemUnderTest(a, WORKER, env=env_a).wait_up(components=["worker"], timeout=60)
        wait_until(lambda: (b / "local.txt").exists(), timeout=30, what="the event on this run's own component status")
        wait_until(lambda: (b / "alarm.txt").exists(), timeout=60, what="the event on run A's topic")
        assert int((b / "alarm.txt").read_text().split()[0]) >= 3
        assert not (b / "failed.txt").exists()  # run A's worker is healthy so far
        (a / "fail").touch()
        wait_until(lambda: (b / "failed.txt").exists(), timeout=60, what="the event on run A's component status")
        assert (b / "failed.txt").read_text().split("\n")[0] == "no path"
        assert (b / "local.txt").read_text().split() == ["active"]
        assert worker.state("worker") == "active" and watcher.state("emos_monitor") == "active"
    finally:
        if worker is not None:
            assert worker.stop() == 0
        assert watcher.stop() == 0
    assert watcher.leftovers() == [] and worker.leftovers() == []
