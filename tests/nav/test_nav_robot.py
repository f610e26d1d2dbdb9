import math

import numpy as np
import pytest

from emos.actors.nav.robot import (
    AngularCtrlLimits,
    LinearCtrlLimits,
    RobotConfig,
    RobotFrames,
    RobotGeometry,
    RobotType,
)

pytestmark = pytest.mark.unit


def test_spec_example_builds_and_radius_matches_geometry():
    cfg = RobotConfig(
        model_type=RobotType.DIFFERENTIAL_DRIVE,
        geometry_type=RobotGeometry.Type.CYLINDER,
        geometry_params=np.array([0.1, 0.3]),
        ctrl_vx_limits=LinearCtrlLimits(max_vel=1.0, max_acc=1.5, max_decel=2.5),
        ctrl_omega_limits=AngularCtrlLimits(max_vel=1.0, max_acc=2.0, max_decel=2.0, max_steer=np.pi / 3),
    )
    assert cfg.radius == pytest.approx(0.1)
    assert cfg.height == pytest.approx(0.3)
    assert cfg.max_curvature == math.inf


@pytest.mark.parametrize(
    "gtype,params,radius",
    [
        (RobotGeometry.Type.BOX, [0.6, 0.8, 0.2], 0.5),
        (RobotGeometry.Type.SPHERE, [0.3], 0.3),
        (RobotGeometry.Type.ELLIPSOID, [0.4, 0.2, 0.1], 0.4),
        (RobotGeometry.Type.CAPSULE, [0.25, 0.5], 0.25),
        (RobotGeometry.Type.CONE, [0.35, 0.5], 0.35),
    ],
)
def test_bounding_radius(gtype, params, radius):
    assert RobotGeometry.radius(gtype, np.array(params)) == pytest.approx(radius)


@pytest.mark.parametrize(
    "gtype,params",
    [
        (RobotGeometry.Type.BOX, [1.0, 1.0]),
        (RobotGeometry.Type.SPHERE, [0.3, 0.2]),
        (RobotGeometry.Type.CYLINDER, [0.3]),
        (RobotGeometry.Type.ELLIPSOID, [0.3, 0.2, -1.0]),
        (RobotGeometry.Type.CONE, [0.3, float("nan")]),
    ],
)
def test_wrong_geometry_params_are_rejected_at_construction(gtype, params):
    with pytest.raises(ValueError, match="geometry_params for " + gtype.name):
        RobotConfig(model_type="OMNI", geometry_type=gtype, geometry_params=np.array(params))


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(max_vel=-1.0, max_acc=1.0, max_decel=1.0), "max_vel"),
        (dict(max_vel=1.0, max_acc=0.0, max_decel=1.0), "max_acc"),
        (dict(max_vel=1.0, max_acc=1.0, max_decel=float("inf")), "max_decel"),
    ],
)
def test_impossible_linear_limits_raise(kwargs, match):
    with pytest.raises(ValueError, match=match):
        LinearCtrlLimits(**kwargs)


def test_impossible_steering_raises():
    with pytest.raises(ValueError, match="max_steer"):
        AngularCtrlLimits(max_vel=1.0, max_acc=1.0, max_decel=1.0, max_steer=2.0)


def test_unknown_model_type_names_choices():
    with pytest.raises(ValueError, match="ACKERMANN"):
        RobotConfig(model_type="TANK", geometry_type="SPHERE", geometry_params=[0.2])


def test_footprint_distance_box_and_ellipse():
    box = RobotConfig(model_type="OMNI", geometry_type="BOX", geometry_params=[1.0, 0.5, 0.3])
    d = box.footprint_distance(np.array([[1.0, 0.0], [0.0, 0.0], [0.5 + 0.3, 0.25 + 0.4]]))
    np.testing.assert_allclose(d, [0.5, -0.25, 0.5], atol=1e-9)
    ell = RobotConfig(model_type="OMNI", geometry_type="ELLIPSOID", geometry_params=[0.5, 0.25, 0.3])
    d = ell.footprint_distance(np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]))
    np.testing.assert_allclose(d, [0.5, 0.75, -0.25], atol=1e-3)


def test_ackermann_wheel_base_and_curvature():
    cfg = RobotConfig(model_type=RobotType.ACKERMANN, geometry_type="BOX", geometry_params=[0.8, 0.4, 0.3])
    assert cfg.wheel_base == pytest.approx(0.8)
    assert cfg.max_curvature == pytest.approx(math.tan(math.pi / 3) / 0.8)


def test_frames_defaults_and_validation():
    frames = RobotFrames()
    assert (frames.world, frames.odom, frames.robot_base) == ("map", "odom", "base_link")
    with pytest.raises(ValueError, match="RobotFrames.scan"):
        RobotFrames(scan="")
