import numpy as np
import pytest

from emos.actors.sim import Box, World, render_topdown

pytestmark = pytest.mark.sim


def test_topdown_png_shows_obstacles_trail_plan_and_goal(tmp_path, make_world):
    world = make_world()
    world.add(Box((2.0, 0.0), (1.0, 1.0)))
    robot = world.add_robot("jackal", (-2.0, 0.0, 0.0))
    robot.command(1.0)
    world.step(150)
    path = tmp_path / "pic.png"
    img = render_topdown(world, path, plan=[(-2, -1), (3, -1)], goal=(3.0, 2.0), goal_radius=0.5,
                         bounds=(-3, -3, 4, 3), pixels_per_m=20)
    assert path.is_file()
    arr = np.asarray(img)
    assert arr.shape == (120, 140, 3)

    def at(x, y):
        return arr[int((3 - y) * 20), int((x + 3) * 20)]

    assert at(2.0, 0.0).tolist() == [90, 90, 100]  # obstacle
    assert at(-1.5, 0.0).tolist() == [30, 90, 220]  # trail
    assert at(0.0, -1.0).tolist() == [40, 170, 60]  # plan
    assert at(3.0, 2.0).tolist() == [220, 40, 40]  # goal cross


def test_gui_request_without_a_display_runs_headless(monkeypatch, caplog):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with World(gui=True) as world:
        assert not world.gui
    assert "no display" in caplog.text


def test_movers_are_drawn_where_they_are_at_the_time_asked(make_world):
    # A process-mode BARN picture is drawn on a world rebuilt at time 0: the movers must be
    # drawn where they were when the trial ended, not where they started.
    from emos.actors.sim import Cylinder
    from emos.actors.sim.moving import MovingObstacle

    world = make_world()
    world.add(MovingObstacle(Cylinder((0.0, 0.0), 0.3), waypoints=[(0.0, -2.0), (0.0, 2.0)], speed=1.0, mode="once"))
    bounds, ppm = (-3, -3, 3, 3), 20

    def colour_at(img, x, y):
        return np.asarray(img)[int((3 - y) * ppm), int((x + 3) * ppm)].tolist()

    start = render_topdown(world, bounds=bounds, pixels_per_m=ppm)
    later = render_topdown(world, bounds=bounds, pixels_per_m=ppm, at_time=3.0)  # 3 m along: at (0, 1)
    # 0.2 m off the path line (drawn in the mover's colour too), inside the 0.3 m cylinder
    assert colour_at(start, 0.2, -2.0) == [200, 120, 30] and colour_at(start, 0.2, 1.0) != [200, 120, 30]
    assert colour_at(later, 0.2, 1.0) == [200, 120, 30] and colour_at(later, 0.2, -2.0) != [200, 120, 30]
