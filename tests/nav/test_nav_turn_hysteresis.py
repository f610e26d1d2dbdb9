"""In-place rotation with the target nearly behind the robot keeps turning one way: the wrapped
heading error flips sign between +-pi with every re-plan's noise, and a Pure Pursuit that followed
it turned back and forth for good (`emos bench costmap --drive`: a robot facing east with KPIECE1's
paths leaving westward at -179..-173 and +165 degrees); and a robot whose arc to its path is
blocked keeps turning towards the path (the turns in place of Pure Pursuit's detours)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav import RobotConfig, RobotGeometry, RobotType
from emos.actors.nav.controllers.pure_pursuit import PurePursuit, PurePursuitConfig

pytestmark = pytest.mark.unit


def _controller() -> PurePursuit:
    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                        geometry_params=np.array([0.2, 0.3]))
    return PurePursuit(robot, PurePursuitConfig())


def test_a_target_behind_is_turned_to_one_way_whatever_side_the_noise_puts_it():
    c = _controller()
    errors = [math.pi - 0.05, -(math.pi - 0.04), math.pi - 0.1, -(math.pi - 0.2), math.pi - 0.3]
    turns = [math.copysign(1.0, c.rotate_command(e)[2]) for e in errors]
    assert len(set(turns)) == 1, turns  # before: alternating with the error's sign
    # Once the error is no longer near +-pi, the turn follows its sign again (and stays ramped down near 0).
    assert c.rotate_command(-1.0)[2] > 0 and c.rotate_command(1.0)[2] < 0
    assert abs(c.rotate_command(0.01)[2]) < abs(c.rotate_command(1.0)[2])


def test_a_turn_that_has_come_round_far_enough_settles_from_either_side():
    c = _controller()
    assert c.rotate_command(math.pi - 0.1)[2] < 0  # no earlier turn: the error's sign decides
    yaw_error = math.pi - 0.1
    for _ in range(200):  # integrate: the robot turns by the command each 0.1 s and the error shrinks
        w = c.rotate_command(yaw_error)[2]
        yaw_error = math.remainder(yaw_error + w * 0.1, 2 * math.pi)
    assert abs(yaw_error) < 0.05


def _drive(c: PurePursuit, path: np.ndarray, obstacles_world: np.ndarray, pose: np.ndarray, steps: int) -> tuple[list[float], np.ndarray, int]:
    """Closed loop on a kinematic robot (0.1 s a step): the in-place turns' rates, the last pose, the last tracked index."""
    c.set_path(path)
    vel, spins, index = np.zeros(3), [], 0
    for _ in range(steps):
        r = c.compute(pose, vel, _to_robot(obstacles_world, pose))
        v, w = float(r.command[0]), float(r.command[2])
        if v == 0.0 and w != 0.0:
            spins.append(w)
        index = int(r.info.get("tracked_index", index))
        if r.status.name == "GOAL_REACHED":
            break
        pose = pose + np.array([v * math.cos(pose[2]) * 0.1, v * math.sin(pose[2]) * 0.1, w * 0.1])
        vel = np.array([v, 0.0, w])
    return spins, pose, index


def _to_robot(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    d = points - pose[:2]
    return np.c_[c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]]


#: 3 m of a KPIECE1 plan (0.1 m apart) from the keepout bench, seed 3: out of the house's doorway
#: at (2.6, 4.0) westwards, then north between the door frame and a keepout zone's west edge
DOORWAY_PLAN = [[2.51, 4.02], [2.43, 4.07], [2.34, 4.12], [2.26, 4.17], [2.2, 4.25], [2.16, 4.34], [2.13, 4.44], [2.13, 4.54],
                [2.14, 4.64], [2.14, 4.74], [2.15, 4.84], [2.15, 4.94], [2.16, 5.03], [2.16, 5.13], [2.17, 5.23], [2.25, 5.28],
                [2.34, 5.33], [2.43, 5.37], [2.52, 5.41], [2.61, 5.45], [2.7, 5.5], [2.74, 5.58], [2.77, 5.68], [2.8, 5.77],
                [2.84, 5.87], [2.87, 5.96], [2.9, 6.06], [2.93, 6.15], [2.96, 6.25], [2.99, 6.34]]
ZONE = (2.4, 4.4, 3.0, 4.8)  # the keepout zone beside it (xmin, ymin, xmax, ymax)


def _outline(x0: float, y0: float, x1: float, y1: float, step: float = 0.025) -> np.ndarray:
    xs, ys = np.arange(x0, x1 + 1e-9, step), np.arange(y0, y1 + 1e-9, step)
    return np.vstack([np.c_[xs, np.full(len(xs), y0)], np.c_[xs, np.full(len(xs), y1)],
                      np.c_[np.full(len(ys), x0), ys], np.c_[np.full(len(ys), x1), ys]])


def test_a_robot_whose_arc_to_the_path_is_blocked_turns_on_towards_it_and_goes():
    """Seen live in the keepout bench: the robot, just through the doorway, faces east with the
    zone's lower edge 6 cm above its footprint while its plan leaves west, then north. The arc
    Pure Pursuit wants (forward, turning left) hits the zone, so it turns in place, and it must
    keep turning left until a way opens: before, each turn's side was read from its offset to
    the arc (+0.2 rad/s against the arc's +1 read as "right"), and the robot turned back and forth
    about -8 degrees for the rest of the leg."""
    import os

    import emos.actors.sim.data as data
    from emos.actors.nav.maps import load_map

    house = load_map(os.path.join(os.path.dirname(data.__file__), "house.yaml"))
    cells = np.argwhere(house.data >= 50)[:, ::-1]
    walls = house.grid_to_world(cells)
    start = np.array([2.574, 4.136, math.radians(-6.7)])
    walls = walls[np.hypot(walls[:, 0] - start[0], walls[:, 1] - start[1]) < 2.0]
    xy = np.asarray(DOORWAY_PLAN)
    spins, pose, index = _drive(_controller(), np.c_[xy, np.zeros(len(xy))], np.vstack([walls, _outline(*ZONE)]), start, steps=300)
    flips = sum(1 for a, b in zip(spins, spins[1:]) if a * b < 0)
    assert flips <= 2, f"turned back and forth {flips} times: {np.round(spins, 2).tolist()[:60]}"
    assert pose[1] > 5.0, f"never went round the zone: ended at {np.round(pose, 2)} (tracked index {index})"
