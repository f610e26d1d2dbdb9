"""The moving-obstacle parts of the mapless navigator: scan tracker, evidence decay, and the
time-indexed arc check, on synthetic scans (exact ray casting of circles and wall segments)."""
import math

import numpy as np
import pytest

from emos.actors.nav.controllers.arcs import ArcConfig, ArcPlanner
from emos.actors.nav.controllers.movers import PredictedMovers, PredictionConfig
from emos.actors.nav.mapping import EvidenceGrid, ScanTracker, TrackerConfig
from emos.actors.nav.robot import AngularCtrlLimits, LinearCtrlLimits, RobotConfig

pytestmark = pytest.mark.unit

BEAMS, FOV = 720, math.radians(270.0)
ANGLES = -FOV / 2 + FOV / (BEAMS - 1) * np.arange(BEAMS)
INC = FOV / (BEAMS - 1)


def cast(origin, circles=(), segments=(), noise=0.0, rng=None, angles=ANGLES):
    """Ranges of beams from ``origin`` (x, y, yaw) against circles (cx, cy, r) and segments."""
    ox, oy, yaw = origin
    a = yaw + angles
    d = np.c_[np.cos(a), np.sin(a)]
    r = np.full(len(angles), np.inf)
    for cx, cy, rad in circles:
        f = np.array([ox - cx, oy - cy])
        b = d @ f
        c = f @ f - rad * rad
        disc = b * b - c
        t = -b - np.sqrt(np.maximum(disc, 0.0))
        r = np.where((disc >= 0) & (t > 0), np.minimum(r, t), r)
    for (x1, y1), (x2, y2) in segments:
        e = np.array([x2 - x1, y2 - y1])
        w = np.array([x1 - ox, y1 - oy])
        den = d[:, 0] * e[1] - d[:, 1] * e[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (w[0] * e[1] - w[1] * e[0]) / den
            u = (w[0] * d[:, 1] - w[1] * d[:, 0]) / den
        ok = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
        r = np.where(ok, np.minimum(r, t), r)
    if noise and rng is not None:
        r = r + rng.normal(0.0, noise, len(angles))
    return r, d


WALLS = (((-1.0, -3.0), (20.0, -3.0)), ((-1.0, 3.0), (20.0, 3.0)))


def test_tracker_estimates_a_crossing_cylinders_velocity_and_ignores_static_things():
    rng = np.random.default_rng(3)
    tracker = ScanTracker(TrackerConfig())
    velocity = np.array([0.1, 0.8])
    origin = (0.0, 0.0, 0.0)
    moving_hits = static_marked = 0
    for k in range(15):  # 1.5 s at 10 Hz
        t = 0.1 * k
        mover = (4.0 + velocity[0] * t, -1.5 + velocity[1] * t, 0.25)
        pillar = (6.0, 1.8, 0.2)  # a static post
        r, d = cast(origin, [mover, pillar], WALLS, noise=0.01, rng=rng)
        hit = np.isfinite(r)
        pts = np.asarray(origin[:2]) + r[hit, None] * d[hit]
        member = tracker.update(t, pts, origin[:2], INC)
        near_mover = np.hypot(pts[:, 0] - mover[0], pts[:, 1] - mover[1]) < mover[2] + 0.05
        moving_hits += int(member[near_mover].sum())
        static_marked += int(member[~near_mover].sum())
    moving = tracker.moving_tracks(1.4)
    assert len(moving) == 1, [(t.position, t.velocity) for t in tracker.tracks]
    track = moving[0]
    assert np.linalg.norm(track.velocity - velocity) < 0.12, track.velocity
    assert np.linalg.norm(track.predict(1.4) - (4.0 + 0.14, -1.5 + 1.12)) < 0.15
    assert 0.15 < track.radius < 0.35
    assert moving_hits > 0 and static_marked == 0  # wall and post never count as moving


def test_tracker_keeps_a_mover_moving_through_a_turn_round():
    rng = np.random.default_rng(5)
    tracker = ScanTracker()
    origin = (0.0, 0.0, 0.0)
    flags = []
    for k in range(35):  # up at 0.8 m/s for 2 s, then back down
        t = 0.1 * k
        y = -1.5 + 0.8 * min(t, 2.0) - 0.8 * max(t - 2.0, 0.0)
        r, d = cast(origin, [(4.0, y, 0.25)], WALLS, noise=0.01, rng=rng)
        hit = np.isfinite(r)
        tracker.update(t, np.asarray(origin[:2]) + r[hit, None] * d[hit], origin[:2], INC)
        flags.append(bool(tracker.moving_tracks(t)))
    first = flags.index(True)
    assert first <= 8 and all(flags[first:]), flags
    (track,) = tracker.moving_tracks(3.4)
    assert np.linalg.norm(track.velocity - (0.0, -0.8)) < 0.15, track.velocity


# A 360-beam lidar (1 degree, the simulator's and an RPLIDAR's), and the simulator's person.
LIDAR_360 = -math.pi + math.radians(1.0) * np.arange(360)
PERSON_RADIUS = 0.22


def test_a_person_walking_at_a_robot_that_drives_at_them_is_moving_before_they_meet():
    """The blind-person patrol's first-lap contact: the robot at 1 m/s into a corridor, the person
    walking down it at it at 0.6 m/s, seen by a 1-degree lidar (12 to 30 hits on them). The track
    moves a metre out, with its velocity."""
    rng = np.random.default_rng(11)
    tracker = ScanTracker()
    walls = (((-1.0, -0.5), (8.0, -0.5)), ((-1.0, 0.5), (8.0, 0.5)))  # a 1 m corridor
    robot_x, person_x, gap_moving = 0.0, 4.5, None
    for k in range(40):
        t = 0.1 * k
        robot_x, person_x = 1.0 * t, 4.5 - 0.6 * t
        gap = person_x - robot_x - PERSON_RADIUS - 0.2
        if gap < 0.0:
            break
        origin = (robot_x, 0.05, 0.02 * math.sin(3.0 * t))  # a slight weave, as a controller steers
        r, d = cast(origin, [(person_x, -0.05, PERSON_RADIUS)], walls, noise=0.005, rng=rng, angles=LIDAR_360)
        hit = np.isfinite(r)
        tracker.update(t, np.asarray(origin[:2]) + r[hit, None] * d[hit], origin[:2], math.radians(1.0))
        if gap_moving is None and any(abs(tr.position[1]) < 0.3 for tr in tracker.moving_tracks(t)):
            gap_moving = gap
    assert gap_moving is not None and gap_moving > 1.0, f"moving at a gap of {gap_moving} m"
    (track,) = [tr for tr in tracker.moving_tracks(t) if abs(tr.position[1]) < 0.3]
    assert np.linalg.norm(track.velocity - (-0.6, 0.0)) < 0.1, track.velocity


def test_tracker_keeps_a_post_static_while_the_robot_drives_past_it():
    rng = np.random.default_rng(4)
    tracker = ScanTracker()
    for k in range(30):  # robot at 1.5 m/s along x past a post 1 m to the side
        t = 0.1 * k
        origin = (0.15 * k, 0.0, 0.0)
        r, d = cast(origin, [(3.0, 1.0, 0.15)], WALLS, noise=0.01, rng=rng)
        hit = np.isfinite(r)
        tracker.update(t, np.asarray(origin[:2]) + r[hit, None] * d[hit], origin[:2], INC)
    assert tracker.moving_tracks(2.9) == []


def test_evidence_decay_releases_a_movers_trail_and_keeps_the_wall():
    grid = EvidenceGrid((-1.0, -4.0, 12.0, 4.0), 0.05)
    origin = (0.0, 0.0, 0.0)

    def scan(t, circles):
        r, d = cast(origin, circles, WALLS)
        hit = np.isfinite(r)
        length = np.where(hit, np.minimum(r, 8.0) - 0.075, 8.0)
        grid.observe_free(origin[:2], d, np.maximum(length, 0.0), t)
        grid.insert(np.asarray(origin[:2]) + r[hit, None] * d[hit])

    for k in range(4):  # an obstacle stands at (4, 0) for four scans, then is gone
        scan(0.1 * k, [(4.0, 0.0, 0.25)])
    ys = grid.origin[1] + (np.arange(grid.shape[0]) + 0.5) * grid.resolution
    near_wall = np.abs(np.abs(ys) - 3.0) < 0.1
    near_obstacle = np.abs(ys) < 0.35
    wall_before = int(grid.occupied[near_wall].sum())
    assert grid.occupied[near_obstacle].sum() >= 10 and wall_before > 200
    for k in range(4, 14):
        scan(0.1 * k, [])
    assert not grid.occupied[near_obstacle].any()  # the trail is released
    assert grid.occupied[near_wall].sum() >= 0.95 * wall_before  # the walls, hit every scan, stay
    # Cells crossed by beams carry the time they were seen free.
    assert grid.seen_free_since(np.array([[3.8, 0.0]]), 1.0)[0]
    assert not grid.seen_free_since(np.array([[3.8, 0.0]]), 1.5)[0]


def test_evidence_grid_rejects_bad_cap():
    with pytest.raises(ValueError, match="cap"):
        EvidenceGrid((0.0, 0.0, 1.0, 1.0), 0.05, cap=0)


def _robot():
    return RobotConfig(model_type="DIFFERENTIAL_DRIVE", geometry_type="BOX",
                       geometry_params=np.array([0.5, 0.43, 0.25]),
                       ctrl_vx_limits=LinearCtrlLimits(max_vel=2.0, max_acc=20.0, max_decel=20.0),
                       ctrl_omega_limits=AngularCtrlLimits(max_vel=4.0, max_acc=25.0, max_decel=25.0))


def test_arcs_wait_for_a_predicted_crosser_and_go_when_it_has_passed():
    planner = ArcPlanner(_robot(), ArcConfig(reverse_speed=0.0))
    pose = np.array([0.0, 0.0, 0.0])
    goal = np.array([10.0, 0.0])

    def ctg(xy):
        return np.hypot(xy[:, 0] - goal[0], xy[:, 1] - goal[1])

    free = planner.choose(pose, np.zeros((0, 2)), ctg)
    assert free is not None and free[0] == pytest.approx(2.0)
    # A cylinder 1.2 m ahead, 1.3 m to the right, crossing left at 1.2 m/s: full speed
    # ahead would meet it; the arcs slow down or wait instead.
    movers = PredictedMovers([[1.2, -1.3]], [[0.0, 1.2]], [0.25], PredictionConfig())
    v, w = planner.choose(pose, np.zeros((0, 2)), ctg, movers=movers)
    assert v < 1.0
    gaps = movers.clearances(planner, pose, planner.groups)
    chosen = int(np.flatnonzero((planner.v == v) & (planner.w == w))[0])
    assert gaps[chosen] > 0
    # The same cylinder already past the corridor's centre line, moving away: full speed.
    gone = PredictedMovers([[1.2, 1.3]], [[0.0, 1.2]], [0.25], PredictionConfig())
    v2, _ = planner.choose(pose, np.zeros((0, 2)), ctg, movers=gone)
    assert v2 == pytest.approx(2.0)


def test_predicted_movers_validate_shapes():
    with pytest.raises(ValueError, match="one row per obstacle"):
        PredictedMovers([[0.0, 0.0]], [[0.0, 0.0], [1.0, 1.0]], [0.2])


def _crossing_run(movers, on_local_map=False):
    """Closed loop at 10 Hz: ArcSampler on a 6 m straight path; a 0.25 m cylinder crosses it
    at x = 2.2 m at 0.55 m/s, reaching the path as the robot (0.5 m/s) would. ``on_local_map``:
    obstacles from a rolling local grid (as the BARN stack's Controller gets them), the scan
    given apart for tracking. Returns (reached, smallest centre distance - radii, statuses,
    steps the controller said it was waiting for a mover)."""
    from emos.actors.nav.controllers import ControlStatus, OccupancyGrid2D, make_controller
    from emos.actors.nav.controllers.arc_sampler import ArcSamplerConfig
    from emos.actors.nav.kinematics import integrate
    from emos.actors.nav.local_map import LocalMapper, MapConfig
    from tests.nav.sim2d import World, make_robot, straight_path

    robot = make_robot("DIFFERENTIAL_DRIVE")
    ctrl = make_controller("ArcSampler", robot, ArcSamplerConfig(movers=movers))
    ctrl.set_path(straight_path(6.0))
    grid = LocalMapper(MapConfig(width=6.0, height=6.0, resolution=0.05), keep_memory=True)
    pose, vel = np.zeros(3), np.zeros(3)
    gap, statuses, waited = math.inf, [], 0
    for step in range(150):
        t = 0.1 * step
        crosser = (2.2, -2.6 + 0.55 * t, 0.25)
        gap = min(gap, math.hypot(pose[0] - crosser[0], pose[1] - crosser[1]) - 0.25 - robot.radius)
        scan = World(circles=[crosser], range_max=8.0).scan(pose)
        if on_local_map:
            local = OccupancyGrid2D(grid.update(scan, pose).copy(), 0.05, grid.origin)
            res = ctrl.compute(pose, vel, local, scan=scan if movers is not None else None)
        else:
            res = ctrl.compute(pose, vel, scan)
        waited += ctrl.waiting
        statuses.append(res.status)
        if res.status is ControlStatus.GOAL_REACHED:
            return True, gap, statuses, waited
        vel = np.asarray(res.command, dtype=float).reshape(-1, 3)[0]
        pose = integrate(pose, vel, 0.1)
    return False, gap, statuses, waited


@pytest.mark.parametrize("on_local_map", [False, True])
def test_arc_sampler_with_movers_waits_for_a_crosser_that_the_static_check_runs_into(on_local_map):
    from emos.actors.nav.controllers import ControlStatus
    from emos.actors.nav.controllers.movers import MoverConfig

    reached, gap, statuses, waited = _crossing_run(MoverConfig(), on_local_map)
    assert reached and gap > 0.0, gap
    assert ControlStatus.BLOCKED not in statuses  # waiting is running
    assert waited > 5  # the crosser within wait_radius: a progress checker must not call it a stall
    _, static_gap, _, never = _crossing_run(None, on_local_map)
    assert static_gap < 0.0 and never == 0  # without prediction the crosser hits it


def test_moving_obstacle_configs_validate_and_the_local_mapper_takes_evidence_decay():
    from emos.actors.nav.components import LocalMapper, LocalMapperConfig
    from emos.actors.nav.controllers.arc_sampler import ArcSampler
    from emos.actors.nav.controllers.movers import MoverConfig
    from emos.actors.nav.mapping import EvidenceConfig
    from emos.actors.nav.navigator import DynamicConfig
    from tests.nav.sim2d import make_robot

    cfg = LocalMapperConfig(mapping_bounds=(0.0, 0.0, 4.0, 4.0), memory_decay={"cap": 3})
    assert cfg.memory_decay == EvidenceConfig(cap=3, free_range=8.0)
    cfg.memory_decay = EvidenceConfig(cap=2, free_range=5.0)  # on assignment too
    from emos.testing import ComponentHarness

    mapper = LocalMapper("mapper", config=cfg)
    with ComponentHarness(mapper, activate=False):  # configured on a real node (it creates its services)
        assert isinstance(mapper._memory.grid, EvidenceGrid) and mapper._memory.grid.cap == 2
        assert mapper._memory.free_range == 5.0
    plain = LocalMapper("plain", config=LocalMapperConfig(mapping_bounds=(0.0, 0.0, 4.0, 4.0)))
    with ComponentHarness(plain, activate=False):
        assert not isinstance(plain._memory.grid, EvidenceGrid)  # static worlds: never forget
    for bad, match in (({"cap": 0}, "cap must be an integer >= 1"), ({"cap": 2.5}, "cap must be an integer"),
                       ({"free_range": -1.0}, "free_range must be"), ({"decay": 3}, "unknown EvidenceConfig field"),
                       (4, "expected an EvidenceConfig")):
        with pytest.raises((ValueError, TypeError), match=match):
            LocalMapperConfig(mapping_bounds=(0.0, 0.0, 4.0, 4.0), memory_decay=bad)
    with pytest.raises(ValueError, match="mapping mode only"):
        LocalMapperConfig(memory_decay=EvidenceConfig())
    with pytest.raises(ValueError, match="wait_radius"):
        MoverConfig(wait_radius=-1.0)
    with pytest.raises(TypeError, match="EvidenceConfig"):
        DynamicConfig(evidence=4)
    sampler = ArcSampler(make_robot("DIFFERENTIAL_DRIVE"))
    with pytest.raises(TypeError, match="scan must be a LaserScan2D"):
        sampler.compute(np.zeros(3), np.zeros(3), None, scan=np.zeros((3, 2)))


def test_memory_mapper_with_evidence_forgets_a_moved_obstacle_and_keeps_walls():
    from emos.actors.nav.controllers.sensors import LaserScan2D
    from emos.actors.nav.mapping import MemoryMapper

    def scan(circles):
        r, _ = cast((0.0, 0.0, 0.0), circles, WALLS)
        return LaserScan2D(ranges=r, angle_min=float(ANGLES[0]), angle_increment=INC, range_max=30.0)

    for cap, forgets in ((3, True), (None, False)):
        mapper = MemoryMapper((-1.0, -4.0, 12.0, 4.0), 0.05, scan_matching=False, evidence_cap=cap)
        for _ in range(3):
            mapper.update(scan([(4.0, 0.0, 0.25)]), np.zeros(3))
        for _ in range(8):
            mapper.update(scan([]), np.zeros(3))
        rows, cols, _ = mapper.grid.cell_of(np.array([[3.76, 0.0], [5.0, 2.99]]))
        assert mapper.grid.occupied[rows[0] - 1: rows[0] + 2, cols[0] - 1: cols[0] + 2].any() != forgets
        wall = mapper.grid.occupied[rows[1] - 1: rows[1] + 2, cols[1] - 20: cols[1] + 20]
        assert wall.any(axis=0).sum() >= 20  # the wall (x 4-6 m; beams hit 27 of its 40 columns) stays
    with pytest.raises(ValueError, match="not both"):
        MemoryMapper((0.0, 0.0, 1.0, 1.0), carve_range=2.0, evidence_cap=3)
