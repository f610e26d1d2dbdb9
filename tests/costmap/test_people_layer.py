"""The people layer (emos.actors.nav.costmap.people): the band of where people walked, as the
Behaviors publish it and the Planner reads it back; its soft cost; and what it does to the
CostToGo routes of the demo house, where the house's person walks the robot's only way between
its two halves (``HOUSE_PERSON_PATH``): with the layer a route crosses that way instead of
following it, so the stretch the passage guard must find a free window for is shorter."""
from __future__ import annotations

import os

import numpy as np
import pytest

pytestmark = pytest.mark.unit

BAND_CLEARANCE = 0.55  # the passage guard's default band_clearance: a path point this near the band is in it


def _house():
    import emos.actors.sim.data as data
    from emos.actors.nav.maps import load_map

    return load_map(os.path.join(os.path.dirname(data.__file__), "house.yaml"))


def _person_band() -> np.ndarray:
    """The 5 cm cells the house's person walks, as MoverMemory.band_cells gives them."""
    from emos.actors.sim.person import HOUSE_PERSON_PATH

    p = np.array(HOUSE_PERSON_PATH)
    line = np.vstack([np.c_[np.linspace(a[0], b[0], 200), np.linspace(a[1], b[1], 200)] for a, b in zip(p[:-1], p[1:])])
    return np.unique(np.round(line / 0.05).astype(np.int64), axis=0) * 0.05


def _robot():
    from emos.actors.nav import RobotConfig, RobotGeometry, RobotType

    return RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                       geometry_params=np.array([0.2, 0.3]))


def _band_stretch(path: np.ndarray, band: np.ndarray) -> float:
    """m of ``path`` from its first to its last point in the band (what the guard must clear)."""
    xy = path[:, :2]
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
    gap = np.hypot(xy[:, None, 0] - band[None, :, 0], xy[:, None, 1] - band[None, :, 1]).min(axis=1)
    inside = np.flatnonzero(gap < BAND_CLEARANCE)
    return float(s[inside[-1]] - s[inside[0]]) if len(inside) else 0.0


def test_the_band_travels_as_an_occupancy_grid_and_comes_back_cell_for_cell():
    from emos.actors.nav.components.convert import grid_map_of, grid_msg
    from emos.actors.nav.costmap import band_grid, walked_points
    from emos.actors.nav.costmap.people import BAND_RESOLUTION, WALKED

    band = _person_band()
    data, origin = band_grid(band)
    assert data.dtype == np.int8 and set(np.unique(data)) == {0, WALKED}
    back = walked_points(grid_map_of(grid_msg(data, BAND_RESOLUTION, origin, "map")))
    order = np.lexsort(band.T[::-1])
    assert back.shape == band.shape
    assert np.allclose(back[np.lexsort(back.T[::-1])], band[order], atol=1e-9)
    empty, _ = band_grid(np.zeros((0, 2)))  # nothing walked yet: a grid with no walked cell
    assert empty.shape == (1, 1) and not empty.any()


def test_the_cost_is_the_weight_near_the_band_and_fades_to_nothing():
    from emos.actors.nav.costmap import PeopleLayerConfig, people_cost

    grid = _house()
    config = PeopleLayerConfig(weight=3.0, inflation=0.55, fade=0.3)
    cost = people_cost(grid, np.array([[4.2, 1.5], [40.0, 40.0]]), config)  # the second is off the map: dropped
    assert cost.shape == grid.data.shape
    centres = grid.grid_to_world(np.stack(np.meshgrid(np.arange(grid.width), np.arange(grid.height)), axis=-1))
    d = np.hypot(centres[..., 0] - 4.2, centres[..., 1] - 1.5)
    assert np.all(cost[d < 0.5] == 3.0)
    assert np.all(cost[d > 0.9] == 0.0)
    fading = (d > 0.6) & (d < 0.8)
    assert np.all((cost[fading] > 0) & (cost[fading] < 3.0))
    assert not people_cost(grid, np.zeros((0, 2)), config).any()
    assert not people_cost(grid, np.array([[4.2, 1.5]]), PeopleLayerConfig(weight=0.0)).any()


def test_bad_people_layer_settings_are_refused_naming_them():
    from emos.actors.nav.costmap import PeopleLayerConfig
    from emos.actors.nav.planning.grid_planner import CostToGoPlanner

    with pytest.raises((ValueError, TypeError), match="weight"):
        PeopleLayerConfig(weight=-1.0)
    with pytest.raises((ValueError, TypeError), match="fade"):
        PeopleLayerConfig(fade=0.0)
    planner = CostToGoPlanner(_robot())
    planner.set_map(_house())
    with pytest.raises(ValueError, match="map's shape"):
        planner.set_extra_cost(np.zeros((3, 3)))
    with pytest.raises(ValueError, match=">= 0"):
        planner.set_extra_cost(np.full(planner.grid.data.shape, -1.0))


@pytest.mark.parametrize("start, goal", [((2.5, 2.0), (7.0, 2.5)), ((8.0, 5.5), (3.5, 5.5))],
                         ids=["left room to right room", "top right to top left"])
def test_with_the_layer_the_house_routes_cross_the_persons_way_instead_of_following_it(start, goal):
    from emos.actors.nav.costmap import PeopleLayerConfig, people_cost
    from emos.actors.nav.planning.grid_planner import CostToGoPlanner

    grid, band = _house(), _person_band()
    planner = CostToGoPlanner(_robot())
    planner.set_map(grid)
    plain = planner.plan(start, goal)
    planner.set_extra_cost(people_cost(grid, band, PeopleLayerConfig(enabled=True)))
    layered = planner.plan(start, goal)
    assert plain.solved and layered.solved
    before, after = _band_stretch(plain.path, band), _band_stretch(layered.path, band)
    # Measured: 2.77 -> 2.19 m and 3.85 -> 2.19 m (through the 0.98 m doorway the person walks, and across
    # its walk up x = 4.2: no route avoids both).
    assert after <= 0.8 * before, (before, after)
    assert layered.length_m <= 1.15 * plain.length_m  # a detour of a few decimetres, not round the house
    planner.set_extra_cost(None)
    assert np.allclose(planner.plan(start, goal).path, plain.path)


# -- through the components, on the component harness (robot time, no process tree) ----------------

BAND_TOPIC = "/people_band"


def _planner(**people):
    from emos.actors.nav import RobotFrames
    from emos.actors.nav.components import Planner, PlannerConfig
    from emos.io.topic import Topic

    planner = Planner(component_name="planner", config=PlannerConfig(
        loop_rate=1.0, planner_id="CostToGo", robot=_robot(), frames=RobotFrames(world="map", odom="map"),
        people={"enabled": True, **people}))
    planner.inputs(people=Topic(name=BAND_TOPIC, msg_type="OccupancyGrid"))
    return planner


def _odom(x: float, y: float):
    from emos import msgs as M

    odom = M.Odometry()
    odom.header.frame_id = "map"
    odom.pose.pose.position.x, odom.pose.pose.position.y = x, y
    odom.pose.pose.orientation = M.Quaternion.from_yaw(0.0)
    return odom


def _path_xy(msg) -> np.ndarray:
    return np.array([(p.pose.position.x, p.pose.position.y) for p in msg.poses])


def test_the_planner_plans_round_the_band_it_is_sent_and_keeps_planning_through_a_bad_one():
    from emos import msgs as M
    from emos.actors.nav.components.convert import grid_msg
    from emos.actors.nav.costmap import band_grid
    from emos.actors.nav.costmap.people import BAND_RESOLUTION
    from emos.testing import ComponentHarness

    house, band = _house(), _person_band()
    with ComponentHarness(_planner(), tick=0.1) as h:
        h.feed("/map", grid_msg(house.data, house.resolution, house.origin, "map"))
        h.feed("/odom", _odom(2.5, 2.0))
        h.feed("/goal", M.PointStamped(header=M.Header(frame_id="map"), point=M.Point(x=7.0, y=2.5)))

        def next_plan():
            mark = h.mark()
            h.advance(1.0)  # a planning period: the plan is computed on the Planner's worker thread
            return _path_xy(h.wait_for(lambda: (h.since("/plan", mark) or [None])[-1], what="the next plan"))

        plain = next_plan()  # no band yet: the plain route
        data, origin = band_grid(band)
        h.feed(BAND_TOPIC, grid_msg(data, BAND_RESOLUTION, origin, "map"))
        layered = next_plan()
        assert _band_stretch(layered, band) <= 0.8 * _band_stretch(plain, band)
        bad = M.OccupancyGrid(header=M.Header(frame_id="map"))  # 0 x 0: refused, the last good band kept
        bad.header.stamp = M.Time.from_sec(h.time)
        h.feed(BAND_TOPIC, bad)
        again = next_plan()
        assert np.allclose(again, layered)
        assert h.health().status == M.ComponentStatus.STATUS_HEALTHY


def test_a_people_layer_without_a_grid_planner_or_a_band_topic_is_refused():
    from emos.actors.nav.components import Planner, PlannerConfig
    from emos.testing import ComponentHarness

    with pytest.raises(ValueError, match="grid planners"):
        PlannerConfig(people={"enabled": True})  # the default planner is OMPL's KPIECE1
    unwired = Planner(component_name="planner", config=PlannerConfig(planner_id="CostToGo", people={"enabled": True}))
    with pytest.raises(Exception, match="'people' input has no topic"):
        ComponentHarness(unwired)


def test_the_behaviors_publish_where_a_person_walked_once_a_second():
    import math

    from emos import msgs as M
    from emos.actors.nav import RobotFrames
    from emos.actors.nav.components.behaviors import Behaviors, BehaviorsConfig
    from emos.actors.nav.components.convert import grid_map_of
    from emos.actors.nav.costmap import walked_points
    from emos.io.topic import Topic
    from emos.testing import ComponentHarness
    from tests.nav.components.fake_base import base_messages

    behaviors = Behaviors("behaviors", config=BehaviorsConfig(robot=_robot(), loop_rate=10.0, frames=RobotFrames(world="map", odom="map"),
                                                              passage_guard={"enabled": True}))
    behaviors.outputs(people=Topic(name=BAND_TOPIC, msg_type="OccupancyGrid"))
    robot, half = (2.0, 1.0, 0.0), 0.15  # in fake_base's 6 x 4 m room
    person = np.array([0.5, 3.0])
    with ComponentHarness(behaviors, start_time=5.0, tick=0.1) as h:
        def walk(h):  # a person (a 0.3 m box) walks past at 0.6 m/s, 2 m from the standing robot, blind
            person[0] += 0.6 * h.tick
            box = (person[0] - half, person[1] - half, person[0] + half, person[1] + half)
            odom, scan = base_messages(robot, 0.0, 0.0, 2 * math.pi, [box])
            odom.header.stamp = scan.header.stamp = M.Time.from_sec(h.time)
            h.feed("/odom", odom)
            h.feed("/scan", scan)

        h.advance(8.0, each_tick=walk)  # x 0.5 -> 5.3
        bands = h.since(BAND_TOPIC, 0, times=True)
    assert bands, "no band published"
    times = np.array([t for t, _ in bands])
    assert np.all(np.diff(times) >= 1.0 - 1e-6) and len(bands) <= 9
    walked = walked_points(grid_map_of(bands[-1][1]))
    assert np.all(np.abs(walked[:, 1] - 3.0) < 0.2), walked  # where the person walked, nowhere else
    assert walked[:, 0].min() < 2.0 and walked[:, 0].max() > 4.0
