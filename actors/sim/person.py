"""A walking person: a textured billboard (what cameras see) on a cylinder (what lidars hit).

Cameras see a 2D figure painted on a double-sided quad that stands in the plane of the
walking direction, so a camera looking across the person's path sees it face-on, as a person
walking past seen from the side. The figure is a dark silhouette on a light panel with
human proportions, which is what the HOG people detector of the local Vision model responds to
(a bare cylinder is not). The collision body is a cylinder of the person's width.

Two pedestrians: the *blind* one (the default) walks its path on the clock whatever is in the
way, through a robot standing still; the *yielding* one (``yielding=True``) behaves as people
do and as social-force pedestrian simulators model them: it looks ``look_ahead`` m along its
way, stops when a robot is in it (nearer than both radii plus ``clearance``), waits, and after
``patience`` s of a blocked way turns back. It sees the robots of its pybullet world (the bodies
with mass: the World's robots; walls and other movers are massless) and nothing else.
"""
from __future__ import annotations

import math
import os
import tempfile
import threading
from pathlib import Path
from typing import Any

import attrs
import numpy as np

from emos.config import validators as V

from .moving import MovingObstacle
from .primitives import Cylinder

PERSON_HEIGHT = 1.75  # m, billboard height; the figure fills most of it
PERSON_WIDTH = 0.8  # m, billboard width (the texture's aspect is 1:2 at 128 x 256 px)
PERSON_RADIUS = 0.22  # m, collision cylinder
_STATE_LOCK = threading.Lock()  # a yielding person's walk is advanced by the physics thread and read by status calls


def draw_person(width: int = 128, height: int = 256) -> np.ndarray:
    """(height, width, 3) uint8: a dark walking figure on a light background."""
    from . import _deps

    Image, ImageDraw = _deps.pil_image(), _deps.pil_draw()
    img = Image.new("RGB", (width, height), (205, 205, 200))
    d = ImageDraw.Draw(img)
    s = height / 300.0  # figure drawn in a 300-unit tall frame, feet near the bottom
    cx = width / 2

    def p(x: float, y: float) -> tuple[float, float]:
        return (cx + x * s, 20 * s + y * s)

    ink = (40, 40, 45)
    r = 17 * s
    hx, hy = p(0, 20)
    d.ellipse([hx - r, hy - r, hx + r, hy + r], fill=ink)  # head
    d.polygon([p(-29, 42), p(29, 42), p(23, 142), p(-23, 142)], fill=ink)  # torso
    for (x0, y0, x1, y1, w) in ((-27, 48, -41, 136, 11), (27, 48, 41, 136, 11),  # arms
                                (-12, 140, -19, 262, 17), (12, 140, 19, 262, 17)):  # legs
        d.line([p(x0, y0), p(x1, y1)], fill=ink, width=max(int(w * s), 1))
    return np.asarray(img)


@attrs.define(eq=False)
class Person(MovingObstacle):
    """A :class:`MovingObstacle` the World draws as a textured figure (see the module doc).
    ``yielding``: stops for a robot in its way (``look_ahead`` m, ``clearance`` m, ``patience`` s)."""

    shape: Cylinder = attrs.field(factory=lambda: Cylinder((0.0, 0.0), PERSON_RADIUS, PERSON_HEIGHT))
    waypoints: np.ndarray = attrs.field(kw_only=True)
    speed: float = attrs.field(default=0.8, converter=float)
    name: str = attrs.field(default="person")
    yielding: bool = attrs.field(default=False, kw_only=True, validator=attrs.validators.instance_of(bool))
    look_ahead: float = attrs.field(default=1.0, kw_only=True, converter=float, validator=V.number(gt=0, le=10, finite=True, what="metres"))
    clearance: float = attrs.field(default=0.15, kw_only=True, converter=float, validator=V.number(ge=0, le=5, finite=True, what="metres"))
    patience: float = attrs.field(default=5.0, kw_only=True, converter=float, validator=V.number(gt=0, le=600, finite=True, what="seconds"))
    # A yielding person's walk: arc length along the path, direction, time, since when blocked,
    # its pose then, how long it has stood; the pybullet client and its own body (create_body).
    _s: float = attrs.field(default=0.0, init=False)
    _dir: float = attrs.field(default=1.0, init=False)
    _t: float = attrs.field(default=0.0, init=False)
    _blocked_since: float | None = attrs.field(default=None, init=False)
    _pose: tuple[float, float, float] | None = attrs.field(default=None, init=False)
    stood: float = attrs.field(default=0.0, init=False)  # s it stood for a robot in its way
    turned_back: int = attrs.field(default=0, init=False)  # times it gave up waiting and turned back
    _client: Any = attrs.field(default=None, init=False, repr=False)
    _body: int | None = attrs.field(default=None, init=False)

    # -- the yielding pedestrian ------------------------------------------------------------------
    def pose_at(self, t: float) -> tuple[float, float, float]:
        """(x, y, heading) at ``t`` s: the scripted walk (blind), or the yielding walk advanced
        to ``t`` (calls for an earlier or the same time get the latest pose)."""
        if not self.yielding:
            return super().pose_at(t)
        with _STATE_LOCK:
            if self._pose is None or t > self._t:
                self._advance(max(float(t), 0.0))
            assert self._pose is not None
            return self._pose

    def _point(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        """Position and unit direction of travel (increasing s) at arc length ``s`` of the path."""
        path = self._path()
        seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        s = min(max(s, 0.0), float(cum[-1]))
        k = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1))
        a, b = path[k], path[k + 1]
        return a + (b - a) * ((s - cum[k]) / seg[k]), (b - a) / seg[k]

    def _length(self) -> float:
        return float(np.sum(np.linalg.norm(np.diff(self._path(), axis=0), axis=1)))

    def _robots(self) -> list[tuple[np.ndarray, float]]:
        """(x, y) and radius of every body with mass in the world (the robots), but its own."""
        client = self._client
        if client is None:
            return []
        out = []
        for i in range(client.getNumBodies()):
            body = client.getBodyUniqueId(i)
            if body == self._body or client.getDynamicsInfo(body, -1)[0] <= 0.0:
                continue
            (x, y, _), _ = client.getBasePositionAndOrientation(body)
            lo, hi = client.getAABB(body)
            out.append((np.array([x, y]), 0.5 * max(hi[0] - lo[0], hi[1] - lo[1])))
        return out

    def _way_blocked(self) -> bool:
        """A robot in its way: nearer than both radii plus ``clearance`` to a point of its path
        ahead, up to ``look_ahead`` m."""
        total = self._length()
        ahead = self._s + self._dir * np.arange(0.05, self.look_ahead + 1e-9, 0.05)
        if self.mode == "loop":
            ahead = np.mod(ahead, total)
        points = np.array([self._point(float(a))[0] for a in np.clip(ahead, 0.0, total)])
        reach = self.shape.radius + self.clearance
        return any(bool(np.any(np.hypot(*(points - xy).T) < reach + radius)) for xy, radius in self._robots())

    def _advance(self, t: float) -> None:
        dt = t - self._t if self._pose is not None else 0.0
        self._t = t
        total = self._length()
        if dt > 0.0 and self._way_blocked():
            self.stood += dt
            if self._blocked_since is None:
                self._blocked_since = t
            elif t - self._blocked_since >= self.patience:  # gives up waiting: back the way it came
                self._dir, self._blocked_since = -self._dir, None
                self.turned_back += 1
        else:
            self._blocked_since = None
            s = self._s + self._dir * self.speed * dt
            if self.mode == "loop":
                s %= total
            elif self.mode == "pingpong":
                while s > total or s < 0.0:  # turns round at the ends
                    s = 2 * total - s if s > total else -s
                    self._dir = -self._dir
            else:
                s = min(max(s, 0.0), total)
            self._s = s
        xy, d = self._point(self._s)
        heading = math.atan2(self._dir * d[1], self._dir * d[0])
        self._pose = (float(xy[0]), float(xy[1]), heading)

    def create_body(self, client: Any) -> int:
        """Make the pybullet body (collision cylinder, billboard visual) in ``client``."""
        from . import _deps

        pb = _deps.pybullet()
        h, w = self.shape.height, PERSON_WIDTH
        # Quad in the body's x-z plane (centred on the body origin, which sits at height h / 2),
        # both windings so it is visible from either side.
        vertices = [[-w / 2, 0, -h / 2], [w / 2, 0, -h / 2], [w / 2, 0, h / 2], [-w / 2, 0, h / 2]] * 2
        uvs = [[0, 0], [1, 0], [1, 1], [0, 1]] * 2
        normals = [[0, -1, 0]] * 4 + [[0, 1, 0]] * 4
        indices = [0, 1, 2, 0, 2, 3, 4, 6, 5, 4, 7, 6]
        col = client.createCollisionShape(pb.GEOM_CYLINDER, radius=self.shape.radius, height=h)
        vis = client.createVisualShape(pb.GEOM_MESH, vertices=vertices, indices=indices, uvs=uvs, normals=normals,
                                       rgbaColor=[1, 1, 1, 1])
        body = client.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=col, baseVisualShapeIndex=vis)
        client.changeVisualShape(body, -1, textureUniqueId=_texture(client))
        self._client, self._body = client, body  # a yielding person looks for robots in this world
        return body


def _texture(client: Any) -> int:
    """Load the figure as a pybullet texture (pybullet loads textures from files only)."""
    from . import _deps

    Image = _deps.pil_image()
    fd, name = tempfile.mkstemp(prefix="emos-person-", suffix=".png")
    os.close(fd)
    try:
        Image.fromarray(draw_person()).save(name)
        return int(client.loadTexture(name))
    finally:
        Path(name).unlink(missing_ok=True)


# In the demo house: from the spawn room, across the robot's view, through the middle doorway
# into the east room (out of view behind the wall) and back.
HOUSE_PERSON_PATH = ((4.2, 0.6), (4.2, 3.25), (7.0, 3.25))


def house_person(yielding: bool = False) -> Person:
    """The demo house's person (``HOUSE_PERSON_PATH`` at 0.6 m/s, back and forth): blind, or
    ``yielding`` (see the module doc), e.g. for ``SimulatorConfig(world="house", moving_obstacles=[...])``."""
    return Person(waypoints=np.array(HOUSE_PERSON_PATH), speed=0.6, mode="pingpong", yielding=yielding)


def house_with_person(yielding: bool = False, **world_kwargs: Any) -> Any:
    """The demo house with a person walking in and out of the view of a robot at the spawn."""
    from .builders import demo_house

    world = demo_house(**world_kwargs)
    world.name = "house_person"
    world.add(house_person(yielding))
    return world
