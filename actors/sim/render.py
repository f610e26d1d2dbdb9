"""Top-down PNG pictures of a world: obstacles, robots and their trails, a plan and a goal."""
from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from . import _deps

if TYPE_CHECKING:
    from .world import World

OBSTACLE = (90, 90, 100)
MOVER = (200, 120, 30)
TRAIL = (30, 90, 220)
PLAN = (40, 170, 60)
GOAL = (220, 40, 40)
POINTS = (230, 150, 0)
ESTIMATE = (150, 60, 190)  # where the navigation stack believed the robot was


def render_topdown(world: World, path: str | Path | None = None, *, plan: Sequence[Sequence[float]] | np.ndarray | None = None,
                   goal: Sequence[float] | None = None, goal_radius: float = 0.0,
                   points: np.ndarray | None = None, bounds: tuple[float, float, float, float] | None = None,
                   pixels_per_m: float = 40.0, title: str | None = None, at_time: float | None = None,
                   estimate: Sequence[Sequence[float]] | np.ndarray | None = None) -> Any:
    """Draw ``world`` seen from above; returns the PIL image and writes it to ``path`` if given.

    ``plan`` is a polyline (N, 2), ``points`` extra world points (a lidar scan, say), ``bounds``
    (xmin, ymin, xmax, ymax) the window (default: everything in the world, goal included).
    ``at_time``: the simulated time to draw moving obstacles at (default: the world's clock).
    ``estimate``: the poses (N, 2+) the navigation stack believed, drawn thin beside the true
    trail with a cross at the last one: where the two part is where localization drifted.
    """
    image_mod, draw_mod = _deps.pil_image(), _deps.pil_draw()
    if bounds is None:
        xmin, ymin, xmax, ymax = world.bounds()
        if goal is not None:
            r = goal_radius + 0.3
            xmin, ymin = min(xmin, goal[0] - r), min(ymin, goal[1] - r)
            xmax, ymax = max(xmax, goal[0] + r), max(ymax, goal[1] + r)
    else:
        xmin, ymin, xmax, ymax = bounds
    width = max(1, int(math.ceil((xmax - xmin) * pixels_per_m)))
    height = max(1, int(math.ceil((ymax - ymin) * pixels_per_m)))
    img = image_mod.new("RGB", (width, height), (250, 250, 250))
    draw = draw_mod.Draw(img)

    def px(xy: np.ndarray) -> list[tuple[float, float]]:
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        u = (xy[:, 0] - xmin) * pixels_per_m
        v = (ymax - xy[:, 1]) * pixels_per_m  # image rows grow downwards, world y upwards
        return list(zip(u.tolist(), v.tolist()))

    # Light 1 m grid for scale.
    for gx in range(math.ceil(xmin), math.floor(xmax) + 1):
        draw.line(px(np.array([[gx, ymin], [gx, ymax]])), fill=(232, 232, 232))
    for gy in range(math.ceil(ymin), math.floor(ymax) + 1):
        draw.line(px(np.array([[xmin, gy], [xmax, gy]])), fill=(232, 232, 232))
    for shape in world.shapes:
        draw.polygon(px(shape.footprint()), fill=OBSTACLE)
    t = world.clock.now() if at_time is None else float(at_time)
    for mover in world.movers:
        x, y, heading = mover.pose_at(t)
        fp = mover.shape.footprint() - np.asarray(mover.shape.center)
        c, s = math.cos(heading), math.sin(heading)
        draw.polygon(px(fp @ np.array([[c, s], [-s, c]]) + (x, y)), fill=MOVER)
        draw.line(px(mover.waypoints), fill=MOVER, width=1)
    if goal is not None:
        r = max(goal_radius, 0.1) * pixels_per_m
        (u, v), = px(np.array([float(goal[0]), float(goal[1])]))
        draw.ellipse([u - r, v - r, u + r, v + r], outline=GOAL, width=2)
        draw.line([(u - 6, v - 6), (u + 6, v + 6)], fill=GOAL, width=2)
        draw.line([(u - 6, v + 6), (u + 6, v - 6)], fill=GOAL, width=2)
    if plan is not None and len(plan) > 1:
        draw.line(px(np.asarray(plan)[:, :2]), fill=PLAN, width=2)
    if points is not None and len(points):
        for u, v in px(np.asarray(points)[:, :2]):
            draw.point((u, v), fill=POINTS)
    if estimate is not None and len(estimate):
        believed = np.asarray(estimate, dtype=float)[:, :2]
        if len(believed) > 1:
            draw.line(px(believed), fill=ESTIMATE, width=1)
        (u, v), = px(believed[-1])
        draw.line([(u - 5, v - 5), (u + 5, v + 5)], fill=ESTIMATE, width=2)
        draw.line([(u - 5, v + 5), (u + 5, v - 5)], fill=ESTIMATE, width=2)
    for robot in world.robots:
        if len(robot.trail) > 1:
            draw.line(px(np.asarray(robot.trail)), fill=TRAIL, width=2)
        x, y, yaw = robot.pose
        c, s = math.cos(yaw), math.sin(yaw)
        fp = robot.spec.footprint() @ np.array([[c, s], [-s, c]]) + (x, y)
        color = (220, 30, 30) if robot.collided else tuple(int(255 * k) for k in robot.spec.color[:3])
        draw.polygon(px(fp), outline=color, width=2)
        nose = np.array([[x, y], [x + c * robot.spec.length * 0.6, y + s * robot.spec.length * 0.6]])
        draw.line(px(nose), fill=color, width=2)
        for contact in robot.contacts:
            (u, v), = px(np.array(contact.position[:2]))
            draw.ellipse([u - 4, v - 4, u + 4, v + 4], outline=(255, 0, 0), width=2)
    if title:
        draw.text((4, 4), title, fill=(0, 0, 0))
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        img.save(path)
    return img
