"""How often a robot could cross the house person's way at all: docs/missions.md, "Routes off the
people's way".

    python3 scripts/passage_windows.py [--weights 0 3 10] [--speeds 0.25 0.4 0.5]

For each of the patrol's two routes through the middle doorway (the CostToGo plan, with the
people layer at each weight on the person's true walk), and each constant speed: the share of
start times (every 0.1 s over the person's 18.2 s cycle) from which a robot driving the route from
0.6 m before the band to its end never comes within robot + person radius + the passage guard's
0.15 m margin of the person (``HOUSE_PERSON_PATH``, back and forth at 0.6 m/s). It knows the
person's walk exactly, so it is the most any guard could let through: where it is small, waiting
outside the band cannot be quick, whatever the prediction.
"""
from __future__ import annotations

import argparse
import os

import numpy as np

from emos.actors.nav import RobotConfig, RobotGeometry, RobotType
from emos.actors.nav.costmap import PeopleLayerConfig, people_cost
from emos.actors.nav.maps import load_map
from emos.actors.nav.missions.passages import PassageGuardConfig
from emos.actors.nav.planning.grid_planner import CostToGoPlanner
from emos.actors.sim.person import HOUSE_PERSON_PATH, PERSON_RADIUS

ROUTES = {"left room -> right room": ((2.5, 2.0), (7.0, 2.5)), "top right -> top left": ((8.0, 5.5), (3.5, 5.5))}
ROBOT_RADIUS, PERSON_SPEED = 0.2, 0.6


def person_at(t: np.ndarray, waypoints: np.ndarray) -> np.ndarray:
    seg = np.hypot(*np.diff(waypoints, axis=0).T)
    cum, length = np.r_[0.0, np.cumsum(seg)], float(seg.sum())
    s = (PERSON_SPEED * t) % (2 * length)
    s = np.where(s > length, 2 * length - s, s)
    return np.c_[np.interp(s, cum, waypoints[:, 0]), np.interp(s, cum, waypoints[:, 1])]


def safe_share(route: np.ndarray, walk: np.ndarray, band: np.ndarray, speed: float, guard: PassageGuardConfig) -> float:
    xy = route[:, :2]
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
    gap = np.hypot(xy[:, None, 0] - band[None, :, 0], xy[:, None, 1] - band[None, :, 1]).min(axis=1)
    inside = np.flatnonzero(gap < guard.band_clearance + guard.approach)
    s0, s1 = s[inside[0]], s[inside[-1]]
    taus = np.arange(0.0, (s1 - s0) / speed, 0.05)
    robot = np.c_[np.interp(s0 + speed * taus, s, xy[:, 0]), np.interp(s0 + speed * taus, s, xy[:, 1])]
    need = ROBOT_RADIUS + PERSON_RADIUS + guard.margin
    cycle = 2 * float(np.hypot(*np.diff(walk, axis=0).T).sum()) / PERSON_SPEED
    starts = np.arange(0.0, cycle, 0.1)
    ok = [np.hypot(*(robot - person_at(t0 + taus, walk)).T).min() > need for t0 in starts]
    return float(np.mean(ok))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--weights", type=float, nargs="+", default=[0.0, 3.0, 10.0], help="people layer weights (0: none)")
    parser.add_argument("--speeds", type=float, nargs="+", default=[0.25, 0.4, 0.5], help="m/s of the drive through")
    args = parser.parse_args()
    import emos.actors.sim.data as data

    grid = load_map(os.path.join(os.path.dirname(data.__file__), "house.yaml"))
    robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                        geometry_params=np.array([ROBOT_RADIUS, 0.3]))
    walk = np.array(HOUSE_PERSON_PATH)
    band = np.vstack([np.c_[np.linspace(a[0], b[0], 200), np.linspace(a[1], b[1], 200)] for a, b in zip(walk[:-1], walk[1:])])
    planner, guard = CostToGoPlanner(robot), PassageGuardConfig()
    planner.set_map(grid)
    print("| route | people layer weight | band stretch (m) | " + " | ".join(f"safe starts at {v} m/s" for v in args.speeds) + " |")
    print("| --- | --- | --- | " + " | ".join("---" for _ in args.speeds) + " |")
    for weight in args.weights:
        planner.set_extra_cost(people_cost(grid, band, PeopleLayerConfig(weight=weight)) if weight > 0 else None)
        for name, (start, goal) in ROUTES.items():
            route = planner.plan(start, goal).path
            xy = route[:, :2]
            s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
            inside = np.flatnonzero(np.hypot(xy[:, None, 0] - band[None, :, 0], xy[:, None, 1] - band[None, :, 1]).min(axis=1)
                                    < guard.band_clearance)
            stretch = s[inside[-1]] - s[inside[0]] if len(inside) else 0.0
            shares = [safe_share(route, walk, band, v, guard) for v in args.speeds]
            print(f"| {name} | {weight:g} | {stretch:.2f} | " + " | ".join(f"{100 * x:.0f} %" for x in shares) + " |")


if __name__ == "__main__":
    main()
