"""Replay recorded mover-tracker inputs (scripts/record_tracker_inputs.py) and score what the
Behaviors would have seen against the house person's scripted walk (docs/missions.md, "The robot
saw with half its beams").

    python3 scripts/replay_tracker.py rec.npz [--walls subtract hits centres none]

``--walls``: how the static map is used, each a row: ``subtract`` (MoverWatch with the map, as
the stack runs it: hits on walls not tracked, tracks on walls left out), ``hits`` (every hit
tracked; tracks whose centre or hits are on walls left out), ``centres`` (only tracks whose centre
is on a wall left out), ``none``. Per row: the share of scans seeing the person (3 hits or more)
in which a mover is within 0.45 m of them (all, and within 1.5 m of the robot); of their
sightings (runs of scans seeing them, gaps under 1 s), how many never had such a mover and the
median delay to the first; the gap at which each approach (from more than 1.2 m to under 0.8 m)
first had one; and the share of scans with a mover 0.6 m or more off the person.
"""
from __future__ import annotations

import argparse
import math
import os

import numpy as np

from emos.actors.nav.controllers.movers import MoverWatch, WallFilter
from emos.actors.sim.data import HOUSE_MAP
from emos.actors.sim.person import house_person

ROBOT_RADIUS = 0.2  # the patrol's robot


def load(path: str) -> list[dict]:
    z = np.load(path)
    points = np.split(z["points"], np.cumsum(z["counts"])[:-1])
    return [dict(stamp=float(z["stamp"][i]), points=points[i], pose=z["pose"][i], angle_increment=float(z["angle_increment"][i]),
                 pose_stamp=None if np.isnan(z["pose_stamp"][i]) else float(z["pose_stamp"][i]), twist=z["twist"][i])
            for i in range(len(z["stamp"]))]


def replay(scans: list[dict], walls_mode: str) -> np.ndarray:
    """Rows (stamp, hits on the person, person tracked, movers off the person, gap robot-person)."""
    walls = WallFilter.from_map_file(str(HOUSE_MAP), 0.1)
    assert walls is not None
    watch = MoverWatch(walls=walls if walls_mode == "subtract" else None)
    person = house_person()
    rows = []
    for scan in scans:
        watch.update(scan["stamp"], scan["points"], scan["pose"], scan["angle_increment"], pose_stamp=scan["pose_stamp"],
                     twist=scan["twist"])
        centres, _, _ = watch.movers()
        if walls_mode in ("hits", "centres") and len(centres):
            tracks = watch.tracker.moving_tracks(watch.stamp)
            on = (walls.tracks_on_walls(centres, [t.points for t in tracks]) if walls_mode == "hits" else walls.on_walls(centres))
            centres = centres[~on]
        x, y, _ = person.pose_at(scan["stamp"])
        at = np.array([x, y])
        yaw = float(scan["pose"][2])
        rot = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
        hits = scan["points"] @ rot.T + scan["pose"][:2]
        seen = int(np.sum(np.hypot(*(hits - at).T) < person.shape.radius + 0.06))
        off = np.hypot(*(centres - at).T) if len(centres) else np.zeros(0)
        rows.append((scan["stamp"], seen, bool(np.any(off < 0.45)), int(np.sum(off >= 0.6)),
                     float(np.hypot(*(at - scan["pose"][:2]))) - person.shape.radius - ROBOT_RADIUS))
    return np.array(rows)


def score(rows: np.ndarray) -> dict:
    t, seen, tracked, off, gap = rows.T
    vis = seen >= 3
    tracked = tracked.astype(bool)
    sightings: list[list[int]] = []  # [first, last] scan index of each sighting
    for k in np.flatnonzero(vis):
        if sightings and t[k] - t[sightings[-1][1]] <= 1.0:
            sightings[-1][1] = int(k)
        else:
            sightings.append([int(k), int(k)])
    delays = []
    for a, b in sightings:
        if t[b] - t[a] >= 0.5:
            first = np.flatnonzero(tracked[a:b + 1])
            delays.append(t[a + first[0]] - t[a] if len(first) else math.inf)
    approaches, k = [], 0
    while k < len(t):  # seen from more than 1.2 m, closing, down to under 0.8 m
        if vis[k] and gap[k] > 1.2:
            j = k
            while j + 1 < len(t) and (vis[j + 1] or t[j + 1] - t[j] < 0.3) and gap[j + 1] < gap[j] + 0.2:
                j += 1
            if gap[k:j + 1].min() < 0.8:
                first = np.flatnonzero(tracked[k:j + 1])
                approaches.append(float(gap[k + first[0]]) if len(first) else None)
            k = j + 1
        else:
            k += 1
    delays_a = np.array(delays)
    near = vis & (gap < 1.5)
    return {"scans": len(t), "tracked": float(tracked[vis].mean()), "tracked_near": float(tracked[near].mean()),
            "sightings": len(delays), "never": int(np.sum(~np.isfinite(delays_a))),
            "median_delay_s": float(np.median(delays_a[np.isfinite(delays_a)])) if np.isfinite(delays_a).any() else math.nan,
            "approach_gaps_m": approaches, "false_scans": float(np.mean(off > 0))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording")
    parser.add_argument("--walls", nargs="+", default=["subtract", "hits", "centres"], choices=["subtract", "hits", "centres", "none"])
    args = parser.parse_args()
    if not os.path.exists(args.recording):
        parser.error(f"recording {args.recording!r}: no such file (record one with scripts/record_tracker_inputs.py)")
    scans = load(args.recording)
    print(f"{args.recording}: {len(scans)} scans, {scans[0]['stamp']:.1f}-{scans[-1]['stamp']:.1f} s")
    for mode in args.walls:
        r = score(replay(scans, mode))
        gaps = [g for g in r["approach_gaps_m"] if g is not None]
        missed = len(r["approach_gaps_m"]) - len(gaps)
        print(f"{mode:9s} person tracked {100 * r['tracked']:.0f} % of the scans seeing them ({100 * r['tracked_near']:.0f} % within "
              f"1.5 m); sightings {r['sightings']}, never tracked {r['never']}, median delay {r['median_delay_s']:.2f} s; "
              f"{len(r['approach_gaps_m'])} approaches, least gap when first tracked "
              f"{min(gaps) if gaps else math.nan:.2f} m ({missed} never); scans with a mover off the person "
              f"{100 * r['false_scans']:.1f} %")


if __name__ == "__main__":
    main()
