"""MapServer + Planner as processes under the supervisor, the Planner with a keepout mask
across the straight route: the plan it publishes goes round the zone, and the global costmap
is on its topic for the UI and ``emos topic echo``."""
from __future__ import annotations

import numpy as np
import pytest

from emos import msgs as M
from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

from .helpers import KEEPOUT, write_room

pytestmark = pytest.mark.process

STACK = """
from emos.actors.nav import RobotConfig, RobotType, RobotGeometry, LinearCtrlLimits, AngularCtrlLimits, RobotFrames
from emos.actors.nav.components import MapServer, MapServerConfig, Planner, PlannerConfig

robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                    geometry_params=np.array([0.15, 0.3]),
                    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.5, max_acc=1.5, max_decel=2.5),
                    ctrl_omega_limits=AngularCtrlLimits(max_vel=1.5, max_acc=3.0, max_decel=3.0))
planner = Planner(component_name="planner", config=PlannerConfig(
    loop_rate=2.0, planner_id="CostToGo", costmap={"enabled": True, "keepout_mask": KEEPOUT_MASK},
    smoother={"enabled": True}))
map_server = MapServer(component_name="map_server", config=MapServerConfig(map_file_path=MAP_FILE))
launcher = Launcher(multi_processing=True)
launcher.kompass(components=[map_server, planner], multiprocessing=True)
launcher.inputs(location=Topic(name="/odom", msg_type="Odometry"))
launcher.robot = robot
launcher.frames = RobotFrames(world="map", odom="map")
launcher.bringup()
"""


def test_planner_process_plans_round_a_keepout_zone(tmp_path):
    from emos.transport.pubsub import Publisher, Subscriber

    map_file, keepout = write_room(tmp_path)
    system = SystemUnderTest(tmp_path, f"MAP_FILE = {map_file!r}\nKEEPOUT_MASK = {keepout!r}\n" + STACK,
                             env={"PYTHONPATH": str(REPO)})
    try:
        system.wait_up(timeout=90, components=["map_server", "planner"])
        plans = Subscriber(system.ctx, "/plan", M.Path, queue_size=10)
        costmaps = Subscriber(system.ctx, "/global_costmap/costmap", M.OccupancyGrid, queue_size=2)
        odom_pub = Publisher(system.ctx, "/odom", M.Odometry, publisher_id="test_odom")
        goal_pub = Publisher(system.ctx, "/goal", M.PointStamped, publisher_id="test_goal")
        odom = M.Odometry()
        odom.header.frame_id = "map"
        odom.pose.pose.position.x, odom.pose.pose.position.y = 1.0, 1.0

        def plan():
            odom_pub.publish(odom)
            goal_pub.publish(M.PointStamped(header=M.Header(frame_id="map"), point=M.Point(x=4.5, y=1.0)))
            got = plans.take()
            return got[-1] if got else None

        msg = wait_until(plan, 60, interval=0.2, what="a plan from the Planner process")
        xy = np.array([(p.pose.position.x, p.pose.position.y) for p in msg.poses])
        assert len(xy) > 10 and np.allclose(xy[-1], (4.5, 1.0), atol=0.05)
        assert not KEEPOUT.contains(xy).any(), "the plan enters the keepout zone"
        assert xy[:, 1].max() > 2.8
        grid = wait_until(lambda: (c := costmaps.take()) and c[-1], 30, what="the global costmap topic")
        cells = np.asarray(grid.data).reshape(grid.info.height, grid.info.width)
        assert cells[20, 60] == 100  # (3.0, 1.0): keepout, lethal
    finally:
        system.stop()
