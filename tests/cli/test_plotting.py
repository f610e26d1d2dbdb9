"""Tracks over a map (``emos.tools.plotting.save_tracks_on_map``: the patrol's contact
pictures): the picture is cropped to the tracks and has them in their colours."""
from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.unit


def test_tracks_on_a_map_are_drawn_where_they_are(tmp_path):
    import matplotlib.image

    from emos.actors.nav.maps import OccupancyGridMap
    from emos.tools.plotting import save_tracks_on_map

    data = np.zeros((100, 100), dtype=np.int8)  # 5 x 5 m at 5 cm, a wall along x = 2.5 m
    data[:, 50] = 100
    grid = OccupancyGridMap(data=data, resolution=0.05, origin=(0.0, 0.0, 0.0))
    t = np.linspace(-20.0, 3.0, 231)
    robot = np.c_[np.full_like(t, 1.0), np.linspace(1.0, 4.0, len(t)), t]  # up x = 1, times from the contact
    out = tmp_path / "contact.png"
    save_tracks_on_map(str(out), grid, "contact", {"robot": robot, "person": robot[:, :2] + [0.5, 0.0]},
                       {"robot": (1.0, 3.6)})
    img = matplotlib.image.imread(str(out))
    assert img.shape[0] > 300 and img.shape[1] > 300
    rgb = img[..., :3]
    blue = (rgb[..., 2] > 0.6) & (rgb[..., 0] < 0.3)  # tab:blue, the robot
    red = (rgb[..., 0] > 0.7) & (rgb[..., 1] < 0.3)  # tab:red, the person
    assert blue.sum() > 50 and red.sum() > 50
    # The person's track is right of the robot's in the picture (x grows to the right).
    assert np.flatnonzero(red.any(axis=0)).mean() > np.flatnonzero(blue.any(axis=0)).mean()
    with pytest.raises(SystemExit, match="must end in"):
        from emos.tools.plotting import check_plot_argument

        check_plot_argument(str(tmp_path / "x.txt"))
