"""Localization-only mode (issue 36): localize against a saved map by scan matching, never
changing it. On a real log (ACES, tuning split, shipped in tests/localization/data): the map of
the log's first scans at its reference poses is saved (pose graph and map_server YAML), and the
same scans, with noisy odometry, are localized in it. On the component harness: the
Mapper saves its pose graph in mapping mode, then a Mapper in localization mode tracks the
robot in it, publishes map -> odom and the map, takes an initial pose and adds nothing."""
from __future__ import annotations

import hashlib
import math

import numpy as np
import pytest

pytest.importorskip("gtsam")

from emos.actors.nav.components.interfaces import SaveMapRequest
from emos.actors.nav.localization import (
    beam_angles,
    build_reference_map,
    compose_pose,
    noisy_odometry,
    read_carmen,
    relative_pose,
)
from emos.actors.nav.mapping.slam import (
    MapLocalizer,
    PoseGraphFileError,
    SlamParams,
    load_posegraph,
    save_posegraph,
)
from emos.actors.nav.maps import save_map
from emos.core.lifecycle import InvalidTransition
from emos.msgs import TFMessage
from emos.msgs.geometry import Point, Pose, PoseWithCovarianceStamped, Quaternion
from emos.msgs.std import Header
from emos.testing import ComponentHarness
from tests.localization.helpers import ACES_LOG, cast, loop_path, room_map
from tests.slam.test_mapper import _mapper, _odom, _scan

pytestmark = pytest.mark.unit

NOISE = (0.01, 0.001, 0.01, 0.001)
N = 80  # ACES' first 80 scans: about 25 m of corridor


def _sha(path) -> str:
    return hashlib.sha1(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def aces_map(tmp_path_factory):
    """The map of ACES' first N scans at the log's reference poses, saved both ways (a pose
    graph file as the Mapper writes it, and map_server YAML + PGM). The Mapper's own SLAM
    writing the graph is the component test below; here the map's poses are the reference's,
    so that the localized poses can be checked against them."""
    log = read_carmen(ACES_LOG)
    scans = log.scans[:N]
    poses = np.array(log.poses[:N])
    params = SlamParams(odom_alphas=tuple(2 * a for a in NOISE))
    folder = tmp_path_factory.mktemp("aces_map")
    graph = save_posegraph(folder / "aces.posegraph.npz", poses, [(s.ranges, beam_angles(len(s.ranges))) for s in scans],
                           resolution=params.resolution, sigma=params.sigma, max_range=params.max_range,
                           min_range=params.min_range)
    grid = build_reference_map(poses, [s.ranges for s in scans], beam_angles(180), resolution=0.05)
    yaml = save_map(grid, folder / "aces.yaml")
    return log, poses, graph, yaml, params


@pytest.mark.parametrize("which", ["posegraph", "yaml"])
def test_localizes_a_real_log_against_its_saved_map_and_never_changes_it(aces_map, which):
    log, poses, graph, yaml, params = aces_map
    path = graph if which == "posegraph" else yaml
    before = {p: _sha(p) for p in (graph, yaml, yaml.with_suffix(".pgm"))}
    odom = noisy_odometry(log.poses[:N], NOISE, seed=7)  # other noise than the map was built with
    loc = MapLocalizer(path, params, start=None if which == "posegraph" else poses[0])
    digest = loc.digest()
    est = np.array([loc.step(odom[i], s.ranges, beam_angles(len(s.ranges))) for i, s in enumerate(log.scans[:N])])
    err = np.hypot(est[:, 0] - poses[:, 0], est[:, 1] - poses[:, 1])
    # Against the poses the map was built from: centimetres, where the odometry alone is a
    # metre or more off by the end.
    odom_in_map = np.array([compose_pose(poses[0], relative_pose(odom[0], o)) for o in odom])
    assert np.max(np.hypot(*(odom_in_map[:, :2] - poses[:, :2]).T)) > 0.5, "the odometry alone drifts"
    assert np.median(err) < 0.05, (which, np.median(err), err.max())
    assert err.max() < 0.3, (which, err.max())
    assert loc.matched >= 0.9 * N and not loc.lost
    # The map is read only: the field, the files.
    assert loc.digest() == digest == loc.map_digest
    assert {p: _sha(p) for p in before} == before
    if which == "posegraph":
        assert np.array_equal(load_posegraph(graph).poses, poses)


def test_a_file_that_is_no_pose_graph_is_a_clear_error(tmp_path):
    bad = tmp_path / "x.posegraph.npz"
    np.savez(bad, poses=np.zeros((2, 3)))
    with pytest.raises(PoseGraphFileError, match="x.posegraph.npz.*missing array"):
        load_posegraph(bad)
    bad.write_bytes(b"not a zip")
    with pytest.raises(PoseGraphFileError, match="cannot read"):
        load_posegraph(bad)
    with pytest.raises(ValueError, match=r"expected a saved pose graph"):
        MapLocalizer(tmp_path / "map.png")


def test_config_needs_a_map_file_in_localization_mode(tmp_path):
    from emos.actors.nav.components.mapper import Mapper, MapperConfig

    with pytest.raises(ValueError, match="map_file"):
        MapperConfig(mode="localization")
    with pytest.raises(ValueError):
        MapperConfig(mode="tracking")
    with pytest.raises(ValueError, match="localize_start"):
        MapperConfig(mode="localization", map_file="a.yaml", localize_start=(0.0, math.nan, 0.0))
    missing = Mapper(component_name="mapper", config=MapperConfig(mode="localization",
                                                                   map_file=str(tmp_path / "none.posegraph.npz")))
    # The configure transition fails with the ConfigError's text: the file and what it is for.
    with pytest.raises(InvalidTransition, match="cannot load map_file.*none.posegraph.npz.*localization-only"), \
            ComponentHarness(missing):
        pass


def _in_map(h) -> np.ndarray:
    tf = h.latest("/tf")
    assert isinstance(tf, TFMessage) and tf.transforms[0].header.frame_id == "map"
    tr = tf.transforms[0].transform
    return np.array([tr.translation.x, tr.translation.y, tr.rotation.yaw()])


def test_mapper_saves_its_graph_then_localizes_in_it_without_adding_nodes(tmp_path):
    grid, path = room_map(), loop_path(40)
    odom = noisy_odometry(path, NOISE, seed=1)
    with ComponentHarness(_mapper()) as h:
        for t, o in zip(path, odom):
            h.feed("/odom", _odom(o))
            h.advance(0.05)
            h.feed("/scan", _scan(cast(grid, t)))
            h.advance(0.05)
        resp = h.call("mapper/save_map", SaveMapRequest(file_location=str(tmp_path), file_name="room"))
        assert resp.success and "pose graph" in resp.message, resp.message
    graph = tmp_path / "room.posegraph.npz"
    saved = load_posegraph(graph)
    assert len(saved.poses) == len(path)
    sha = _sha(graph)
    # The map frame is the first odometry pose (= path[0]); drive the loop again on other noise.
    odom2 = noisy_odometry(path, NOISE, seed=5)
    mapper = _mapper(mode="localization", map_file=str(graph))
    with ComponentHarness(mapper) as h:
        errs = []
        for t, o in zip(path, odom2):
            h.feed("/odom", _odom(o))
            h.advance(0.05)
            h.feed("/scan", _scan(cast(grid, t)))
            h.advance(0.05)
            errs.append(math.hypot(*(compose_pose(_in_map(h), o)[:2] - t[:2])))
        assert max(errs) < 0.1, max(errs)
        assert math.hypot(*(odom2[-1, :2] - path[-1, :2])) > 0.1, "the odometry alone drifted"
        m = h.latest("/map")
        assert m is not None and m.header.frame_id == "map" and int(m.info.width) > 100
        assert len(h.outputs("/map")) == 1  # a fixed map: published once (TRANSIENT_LOCAL)
        # An initial pose moves the estimate (RViz's 2D Pose Estimate), even without motion.
        wrong = PoseWithCovarianceStamped(header=Header(frame_id="map"))
        target = path[10]
        wrong.pose.pose = Pose(position=Point(x=float(target[0]) + 0.15, y=float(target[1]) - 0.1),
                               orientation=Quaternion.from_yaw(float(target[2]) + 0.05))
        h.feed("/initialpose", wrong)
        o = noisy_odometry(path, NOISE, seed=5)[-1]
        h.feed("/odom", _odom(o))
        h.advance(0.05)
        h.feed("/scan", _scan(cast(grid, target)))
        h.advance(0.05)
        assert math.hypot(*(compose_pose(_in_map(h), o)[:2] - target[:2])) < 0.05
        assert h.health.is_healthy
        assert mapper.localizer is not None and mapper.localizer.digest() == mapper.localizer.map_digest
        assert mapper.trajectory.shape == (0, 3)  # no SLAM node in localization mode
    assert _sha(graph) == sha
