"""Message stamps follow the node's clock: simulated seconds when the run uses them.

Each test runs a real component in ``emos.testing.ComponentHarness``, whose manual ``/clock``
starts at 1000 s (far from any wall clock reading), and checks the header stamps of what the
component publishes against the harness's time. A stamp taken from the wall clock would sit
beside sim-time ages (the Controller's ``clock.now() - header.stamp``) decades apart.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from emos import Topic
from emos import msgs as M
from emos.core import clock
from emos.testing import ComponentHarness

pytestmark = pytest.mark.unit

SIM_START = 1000.0


def test_clock_stamp_is_the_driven_time_and_the_wall_clock_outside_a_simulation():
    from emos.actors.nav.components import MapServer, MapServerConfig

    before = time.time()
    assert clock.stamp().to_sec() == pytest.approx(before, abs=60.0)  # no simulator: the wall clock
    ms = MapServer(component_name="map_server", config=MapServerConfig(map_file_path=_rooms_map()))
    with ComponentHarness(ms, start_time=SIM_START) as h:
        h.advance(2.0)
        assert clock.stamp().to_sec() == pytest.approx(h.time) == pytest.approx(SIM_START + 2.0)


def _rooms_map() -> str:
    import emos.actors.nav as nav

    path = Path(nav.__file__).parent / "data" / "rooms.yaml"
    assert path.exists(), path
    return str(path)


def test_the_map_server_stamps_its_map_on_the_simulated_clock():
    from emos.actors.nav.components import MapServer, MapServerConfig

    ms = MapServer(component_name="map_server", config=MapServerConfig(map_file_path=_rooms_map()))
    with ComponentHarness(ms, start_time=SIM_START) as h:
        grid = h.latest("/map")  # published on activation, at the harness's start time
        assert grid is not None and grid.info.width > 0
        assert grid.header.stamp.to_sec() == pytest.approx(SIM_START)
        assert grid.info.map_load_time.to_sec() == pytest.approx(SIM_START)


def test_an_agents_component_stamps_its_output_on_the_simulated_clock():
    """VideoMessageMaker builds its Video in its model worker thread: the stamp is still the
    node's clock, which the harness holds at 1003 s while the worker runs."""
    from emos.actors.agents.components import VideoMessageMaker
    from emos.actors.agents.components.video_message_maker import VideoMessageMakerConfig

    camera = Topic(name="camera", msg_type="Image")
    vmm = VideoMessageMaker(component_name="video_maker", inputs=[camera], outputs=[Topic(name="video", msg_type="Video")],
                            config=VideoMessageMakerConfig(min_video_frames=2, max_video_frames=2))
    frame = np.zeros((8, 8, 3), dtype=np.uint8)
    with ComponentHarness(vmm, start_time=SIM_START) as h:
        h.advance(3.0)
        for _ in range(2):
            h.feed(camera, M.Image.from_numpy(frame, encoding="rgb8"))
        h.step()
        deadline = time.monotonic() + 60.0  # only bounds a hang: the worker publishes in milliseconds
        videos: list = []
        while not videos and time.monotonic() < deadline:
            videos = h.outputs("/video")
            if not videos:
                time.sleep(0.01)
        assert videos, "the VideoMessageMaker published no video"
        assert h.time == pytest.approx(SIM_START + 3.0)
        assert videos[0].header.stamp.to_sec() == pytest.approx(h.time)


def test_a_process_that_finds_the_simulator_reads_its_time_at_once():
    """A component without ``use_sim_time`` follows the run's /clock passively: its first reading
    after it finds the simulator is the newest tick, not the wall clock until the next tick
    (a stamp written in between would sit decades beside the simulated ones)."""
    from emos.transport.context import RunContext
    from emos.transport.pubsub import Publisher

    ctx = RunContext.create()
    pub = Publisher(ctx, clock.CLOCK_TOPIC, M.Clock, publisher_id="sim", depth=8)
    follower = None
    try:
        pub.publish(M.Clock(clock=M.Time.from_sec(12.5)))
        follower = clock.run_clock(ctx)
        assert follower.time() == pytest.approx(12.5)
        pub.publish(M.Clock(clock=M.Time.from_sec(13.0)))
        assert follower.time() == pytest.approx(13.0)
        assert follower.time() == pytest.approx(13.0)  # no new tick: the newest one still holds
    finally:
        if follower is not None and follower._sub is not None:
            follower._sub.close()
        pub.close()
        ctx.remove_everything()
