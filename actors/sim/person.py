"""A walking person: a textured billboard (what cameras see) on a cylinder (what lidars hit).

Cameras see a 2D figure painted on a double-sided quad that stands in the plane of the
walking direction, so a camera looking across the person's path sees it face-on, as a person
walking past seen from the side. The figure is a dark silhouette on a light panel with
human proportions, which is what the HOG people detector of the local Vision model responds to
(a bare cylinder is not). The collision body is a cylinder of the person's width.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import attrs
import numpy as np

from .moving import MovingObstacle
from .primitives import Cylinder

PERSON_HEIGHT = 1.75  # m, billboard height; the figure fills most of it
PERSON_WIDTH = 0.8  # m, billboard width (the texture's aspect is 1:2 at 128 x 256 px)
PERSON_RADIUS = 0.22  # m, collision cylinder


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
    """A :class:`MovingObstacle` the World draws as a textured figure (see the module doc)."""

    shape: Cylinder = attrs.field(factory=lambda: Cylinder((0.0, 0.0), PERSON_RADIUS, PERSON_HEIGHT))
    waypoints: np.ndarray = attrs.field(kw_only=True)
    speed: float = attrs.field(default=0.8, converter=float)
    name: str = attrs.field(default="person")

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


def house_with_person(**world_kwargs: Any) -> Any:
    """The demo house with a person walking in and out of the view of a robot at the spawn."""
    from .builders import demo_house

    world = demo_house(**world_kwargs)
    world.name = "house_person"
    world.add(Person(waypoints=np.array(HOUSE_PERSON_PATH), speed=0.6, mode="pingpong"))
    return world
