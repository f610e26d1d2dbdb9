"""Where BARN worlds come from: the copy shipped in the package, and a clone of the official
repository (``--barn-repo``: SDF world files and .npy path files, parsed here from a small
synthetic sample in that format)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.sim.barn_repo import load_barn_repo, parse_world_file, path_cell_to_world, reference_path_length
from emos.actors.sim.barn_worlds import BARN_GOAL, BARN_START, default_worlds_file, load_barn_worlds

pytestmark = pytest.mark.sim

CYLINDER_MODEL = """    <model name='unit_cylinder_{i}'>
      <static>1</static>
      <pose frame=''>{x:.6f} {y:.6f} 0.000000 0.000000 0.000000 0.000000</pose>
      <link name='link'>
        <collision name='collision'>
          <geometry><cylinder><radius>{r:.6f}</radius><length>1</length></cylinder></geometry>
        </collision>
        <visual name='visual'>
          <geometry><cylinder><radius>{r:.6f}</radius><length>1</length></cylinder></geometry>
        </visual>
      </link>
    </model>
"""


def _world_sdf(centres, radius=0.075):
    models = "".join(CYLINDER_MODEL.format(i=i, x=x, y=y, r=radius) for i, (x, y) in enumerate(centres))
    return ("<sdf version='1.6'>\n  <world name='default'>\n"
            "    <light name='sun' type='directional'><pose frame=''>0 0 10 0 -0 0</pose></light>\n"
            "    <model name='ground_plane'><static>1</static><link name='link'><collision name='collision'>"
            "<geometry><plane><normal>0 0 1</normal><size>100 100</size></plane></geometry></collision></link></model>\n"
            + models + "  </world>\n</sdf>\n")


def _fake_repo(root, worlds):
    folder = root / "jackal_helper" / "worlds" / "BARN"
    (folder / "path_files").mkdir(parents=True)
    for idx, (centres, cells) in worlds.items():
        (folder / f"world_{idx}.world").write_text(_world_sdf(centres))
        np.save(folder / "path_files" / f"path_{idx}.npy", np.asarray(cells))
    return folder


def test_the_worlds_ship_inside_the_package_with_their_licence():
    path = default_worlds_file()
    assert "shared" not in path.parts and path.is_file()
    assert "MIT License" in (path.parent / "LICENSE").read_text()
    worlds = load_barn_worlds()
    assert len(worlds) == 250 and all(i % 6 != 0 for i in worlds)


def test_barn_repo_parser_reads_world_and_path_files(tmp_path):
    centres0 = [(-0.075, 0.075), (-1.5, 6.2), (-3.0, 9.9)]
    centres6 = [(-2.0, 7.0)]
    cells = [[15, 0], [15, 10], [16, 20], [15, 30], [15, 45]]
    _fake_repo(tmp_path, {0: (centres0, cells), 6: (centres6, cells[:2])})
    worlds = load_barn_repo(tmp_path)
    assert sorted(worlds) == [0, 6]  # indices the packaged file leaves out (held-out) are read too
    np.testing.assert_allclose(worlds[0].cylinders, centres0)
    np.testing.assert_allclose(worlds[6].cylinders, centres6)
    # Path cells -> metres as the challenge's run.py does: 0.15 m cells, corner at (-4.575, 5.075).
    np.testing.assert_allclose(path_cell_to_world([[0, 0], [15, 10]]), [[-4.575, 5.075], [-2.325, 6.575]])
    poly = np.vstack([BARN_START[:2], path_cell_to_world(cells), BARN_GOAL])
    expected = sum(math.dist(a, b) for a, b in zip(poly[:-1], poly[1:]))
    assert worlds[0].path_length == pytest.approx(expected)
    assert reference_path_length(cells) == pytest.approx(expected)
    # The loader takes a directory as a repository clone (or the world folder itself).
    assert sorted(load_barn_worlds(tmp_path)) == [0, 6]
    assert sorted(load_barn_worlds(tmp_path / "jackal_helper" / "worlds" / "BARN")) == [0, 6]


def test_barn_repo_errors_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="Daffan/the-barn-challenge"):
        load_barn_repo(tmp_path)
    folder = _fake_repo(tmp_path, {3: ([(-1.0, 5.0)], [[1, 1], [2, 2]])})
    (folder / "world_4.world").write_text(_world_sdf([(-1.0, 5.0)]))
    with pytest.raises(FileNotFoundError, match=r"path_<i>.npy for world\(s\) \[4\]"):
        load_barn_repo(tmp_path)
    bad = tmp_path / "bad.world"
    bad.write_text(_world_sdf([(-1.0, 5.0)], radius=0.3))
    with pytest.raises(ValueError, match="radius"):
        parse_world_file(bad)
    bad.write_text("<sdf><world")
    with pytest.raises(ValueError, match="not valid SDF"):
        parse_world_file(bad)


def test_simulator_builds_a_world_from_a_repo_clone(tmp_path):
    from emos.actors.sim.component import SimulatorConfig
    from emos.actors.sim.component.worlds import build_world

    _fake_repo(tmp_path, {12: ([(-2.0, 6.0), (-1.0, 7.0)], [[15, 0], [15, 30]])})
    cfg = SimulatorConfig(world="barn:12", barn_source=str(tmp_path))
    world = build_world(cfg)
    try:
        assert len(world.shapes) == 2
    finally:
        world.close()
    with pytest.raises(ValueError, match="no BARN world 13"):
        SimulatorConfig(world="barn:13", barn_source=str(tmp_path))
    with pytest.raises(ValueError, match="barn_source"):  # whichever validator runs first names it
        SimulatorConfig(world="barn:1", barn_source=str(tmp_path / "missing"))


def test_a_worlds_file_is_parsed_once_and_again_when_it_changes(tmp_path):
    import json
    import os

    from emos.actors.sim.barn_worlds import load_barn_worlds

    path = tmp_path / "w.json"
    path.write_text(json.dumps({"5": {"cylinders": [[0.0, 1.0]], "path_length": 10.0}}))
    first = load_barn_worlds(path)
    again = load_barn_worlds(path)
    assert again is not first and again[5] is first[5]  # the parsed worlds, a fresh dict
    assert not first[5].cylinders.flags.writeable  # nobody can change what the others read
    path.write_text(json.dumps({"5": {"cylinders": [[0.0, 2.0], [1.0, 1.0]], "path_length": 12.0}}))
    os.utime(path, ns=(1, 1))  # even a rewrite within the same timestamp tick is seen: the size differs
    changed = load_barn_worlds(path)
    assert changed[5].path_length == 12.0 and changed[5].cylinders.shape == (2, 2)
