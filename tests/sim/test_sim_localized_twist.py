"""The BARN stack's localized pose (an Odometry from the LocalMapper) carries the simulated base's
measured twist in the body frame: forward speed and counter-clockwise turn rate, unrotated by
the map correction, as the Controller's response model reads it (velocity_of)."""
import math

import numpy as np
import pytest

from emos.actors.nav.components import LocalMapper, LocalMapperConfig
from emos.actors.nav.components.convert import BadInput, localized_odometry, pose_of, pose_stamped, velocity_of
from emos.actors.sim.sensors import WheelImuOdometry
from emos.io.topic import Topic
from emos.msgs import PoseStamped

pytestmark = pytest.mark.sim


def test_a_left_turn_heading_north_reads_forward_and_counter_clockwise(make_world):
    world = make_world(ground=False, seed=1)
    robot = world.add_robot("jackal-barn", (0.0, 0.0, math.pi / 2))  # heading north, as BARN starts
    odom = world.add_sensor(WheelImuOdometry(robot))
    for _ in range(100):
        robot.command(0.6, 0.0, 0.4)
        world.step()
    truth = np.asarray(robot.twist, dtype=float)
    # The base drives forward and turns left, less than commanded (the skid-steer's yaw gain:
    # what the response model learns from this twist).
    assert truth[0] > 0.5 and 0.05 < truth[2] < 0.4
    measured = odom.read(world.clock.now()).to_msg()
    # A map correction that moved and turned the pose (scan matching) does not touch the twist.
    corrected = pose_stamped(0.4, 2.1, math.pi / 2 + 0.3, "map")
    loc = localized_odometry(corrected, measured, "base_link")
    v = velocity_of(loc)
    assert v is not None and v[0] == pytest.approx(truth[0], rel=0.1) and v[2] == pytest.approx(truth[2], rel=0.2)
    assert abs(v[1]) < 1e-9  # not a world-frame twist: heading north that would be (0, +0.6)
    assert np.allclose(pose_of(loc), (0.4, 2.1, math.pi / 2 + 0.3))
    assert loc.header.frame_id == "map" and loc.child_frame_id == "base_link"
    with pytest.raises(BadInput, match="needs the odometry it corrects"):
        localized_odometry(corrected, PoseStamped(), "base_link")


def test_an_odometry_localized_pose_needs_an_odometry_location():
    mapper = LocalMapper("mapper", config=LocalMapperConfig(mapping_bounds=(0.0, 0.0, 4.0, 4.0)))
    mapper.outputs(localized_pose=Topic(name="/local_map/pose", msg_type="Odometry"))
    mapper.inputs(location=Topic(name="/amcl_pose", msg_type="PoseStamped"))
    with pytest.raises(ValueError, match="location input must be an Odometry topic too; got /amcl_pose"):
        mapper.custom_on_configure()
