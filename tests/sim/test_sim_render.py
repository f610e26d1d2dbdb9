import numpy as np
import pytest

from emos.actors.sim import Box, World, render_topdown


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
