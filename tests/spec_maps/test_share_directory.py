"""emos.packages.get_package_share_directory: the spec's ``get_package_share_directory("kompass_sim")``
lines port by changing the import only (issue 33 item 3). The share directories belong to higher
layers, which register them through the ``emos.packages`` entry points (core imports no actor)."""
from __future__ import annotations

import os
import runpy
import subprocess
import sys
from pathlib import Path

import pytest

from emos.errors import EmosError
from emos.packages import GROUP, PackageNotFoundError, get_package_share_directory, get_packages_with_share_directories

pytestmark = pytest.mark.unit

# The spec's lines, verbatim (recipes/navigation/*.md of emos-docs.md), with the ament import
# replaced by ours: the only change a port makes.
SPEC_LINES = """
import os
from emos.packages import get_package_share_directory
kompass_sim_dir = get_package_share_directory(package_name="kompass_sim")
map_file = os.path.join(kompass_sim_dir, "maps", "turtlebot3_webots.yaml")
house_file = os.path.join(kompass_sim_dir, "maps", "turtlebot3_gazebo_house.yaml")
"""


def _register(site: Path, dist: str, entries: dict[str, str]) -> None:
    """A real installed distribution (a dist-info folder on sys.path) declaring share directories."""
    info = site / f"{dist}-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[{GROUP}]\n" + "".join(f"{k} = {v}\n" for k, v in entries.items()))


def test_the_spec_lines_find_the_kompass_sim_maps_by_changing_only_the_import(tmp_path):
    script = tmp_path / "spec_lines.py"
    script.write_text(SPEC_LINES)
    scope = runpy.run_path(str(script))
    assert Path(scope["kompass_sim_dir"]).is_absolute() and isinstance(scope["kompass_sim_dir"], str)
    for key in ("map_file", "house_file"):
        yaml_file = Path(scope[key])
        assert yaml_file.is_file() and yaml_file.with_suffix(".pgm").is_file(), yaml_file
    assert get_package_share_directory("kompass_sim") == scope["kompass_sim_dir"]  # positional, as ament allows
    assert "kompass_sim" in get_packages_with_share_directories()


def test_an_unknown_package_is_a_clear_error_listing_the_known_ones():
    with pytest.raises(PackageNotFoundError, match=r"package 'kompass_simm' not found.*group 'emos.packages'.*"
                                                   r"known packages: .*kompass_sim") as err:
        get_package_share_directory(package_name="kompass_simm")
    # ament's PackageNotFoundError is a KeyError: code written against it keeps working.
    assert isinstance(err.value, KeyError) and isinstance(err.value, EmosError)
    assert not str(err.value).startswith('"')  # the message reads as a message, not a quoted key
    with pytest.raises(TypeError, match="package_name must be a non-empty str"):
        get_package_share_directory("")


def test_a_higher_layer_registers_its_share_directory_through_the_entry_point(tmp_path, monkeypatch):
    pkg = tmp_path / "emos_test_share_pkg_h3"
    (pkg / "maps").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "maps" / "room.yaml").write_text("image: room.pgm\n")
    _register(tmp_path, "emos_test_share_dist", {"my_robot_sim": "emos_test_share_pkg_h3"})
    monkeypatch.syspath_prepend(str(tmp_path))
    share = get_package_share_directory(package_name="my_robot_sim")
    assert Path(share) == pkg.resolve()
    assert os.path.isfile(os.path.join(share, "maps", "room.yaml"))
    assert {"kompass_sim", "my_robot_sim"} <= set(get_packages_with_share_directories())


def test_broken_registrations_name_the_package_and_the_entry_point(tmp_path, monkeypatch):
    _register(tmp_path, "emos_test_share_broken", {"ghost_sim": "emos_test_no_such_module_h3",
                                                   "kompass_sim": "emos_test_no_such_module_h3"})
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(PackageNotFoundError, match=r"package 'ghost_sim'.*\(emos_test_no_such_module_h3\) cannot be "
                                                   r"imported: No module named 'emos_test_no_such_module_h3'"):
        get_package_share_directory("ghost_sim")
    with pytest.raises(PackageNotFoundError, match="'kompass_sim' is registered more than once.*emos.actors.sim.data.kompass_sim"):
        get_package_share_directory("kompass_sim")


def test_asking_for_a_share_directory_imports_no_actor_beyond_the_registered_one():
    code = ("import sys\nfrom emos.packages import get_package_share_directory\n"
            "get_package_share_directory('kompass_sim')\n"
            "print(sorted(m for m in sys.modules if m.startswith(('emos.actors', 'emos.supervisor', 'emos.tools'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    # Only the share directory's own package (and the packages above it) is imported.
    assert out.stdout.strip() == str(["emos.actors", "emos.actors.sim", "emos.actors.sim.data", "emos.actors.sim.data.kompass_sim"])
