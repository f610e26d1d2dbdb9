"""The Launcher finds the web UI and the Foxglove view through entry points (emos/frontends.py),
so core never imports an actor (issue 32, tests/test_layers.py checks the import direction)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from emos import Launcher, Topic
from emos.errors import EmosError
from emos.frontends import GROUP, FrontendUnavailable, _install_hint, load_frontend

pytestmark = pytest.mark.unit


def _register(site: Path, dist: str, entries: dict[str, str]) -> None:
    """A real installed distribution (a dist-info folder on sys.path) declaring frontends."""
    info = site / f"{dist}-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[{GROUP}]\n" + "".join(f"{k} = {v}\n" for k, v in entries.items()))


def test_the_shipped_frontends_are_registered_with_request_and_add():
    for name in ("ui", "foxglove"):
        frontend = load_frontend(name)
        assert callable(frontend.request) and callable(frontend.add)


def test_importing_the_launcher_imports_no_actor():
    code = ("import sys, emos, emos.launcher\n"
            "print(sorted(m for m in sys.modules if m.startswith(('emos.actors', 'emos.supervisor', 'emos.tools'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == "[]"


def test_enable_ui_and_enable_foxglove_work_through_the_hook():
    text = Topic(name="words", msg_type="String")
    launcher = Launcher()
    launcher.enable_ui(outputs=[text], port=5055)
    assert launcher._ui["config"].port == 5055 and launcher._ui["outputs"] == [text]
    with pytest.raises(TypeError, match="unexpected argument"):  # still checked at the recipe's call
        launcher.enable_ui(outputs=[text], colour="red")
    launcher.enable_foxglove(port=0)
    (group,) = [p for p in launcher._packages if p.name == "foxglove"]
    assert type(group.components[0]).__name__ == "FoxgloveBridgeComponent" and group.components[0].config.port == 0


def test_a_missing_frontend_names_itself_and_the_extra():
    with pytest.raises(FrontendUnavailable, match=r"frontend 'hologram' is not installed .*group 'emos.frontends'"):
        load_frontend("hologram")
    with pytest.raises(ImportError):  # callers written against ImportError keep working
        load_frontend("hologram")
    assert issubclass(FrontendUnavailable, EmosError)


def test_two_registrations_of_one_name_are_refused_naming_both(tmp_path, monkeypatch):
    _register(tmp_path, "emos_test_broken_frontend", {"ui": "emos_test_no_such_module_h1"})
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(FrontendUnavailable, match="registered more than once.*emos.actors.ui.frontend.*emos_test_no_such_module_h1"):
        load_frontend("ui")


def test_a_registered_frontend_whose_import_fails_says_what_to_install(tmp_path, monkeypatch):
    _register(tmp_path, "emos_test_broken_viewer", {"viewer3d": "emos_test_no_such_module_h1"})
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(FrontendUnavailable, match=r"frontend 'viewer3d' \(emos_test_no_such_module_h1\) cannot be imported: "
                                                  r"No module named 'emos_test_no_such_module_h1'") as err:
        load_frontend("viewer3d")
    assert isinstance(err.value.__cause__, ModuleNotFoundError)


def test_the_install_hint_names_each_shipped_frontends_extra():
    # The shipped frontends are installed here, so their "not installed" message is checked
    # through the hint it carries.
    assert "pip install 'emos[ui]'" in _install_hint("ui")
    assert "pip install 'emos[ecosystem]'" in _install_hint("foxglove")
    assert "pip install -e ." in _install_hint("ui")  # a checkout installed before the hook existed


def test_a_frontend_without_request_and_add_is_refused(tmp_path, monkeypatch):
    (tmp_path / "emos_test_half_frontend_h1.py").write_text("def request(**options):\n    return options\n")
    _register(tmp_path, "emos_test_half_frontend", {"half": "emos_test_half_frontend_h1"})
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(FrontendUnavailable, match=r"'half' .* has no add\(\) function"):
        load_frontend("half")
