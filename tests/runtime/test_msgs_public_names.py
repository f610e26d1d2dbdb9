"""``emos.msgs.__all__`` is spelled out (so that ruff and mypy see the package's public names):
it must keep listing exactly what the package offers, as the ``dir()`` it replaced did."""
import pytest

import emos.msgs

pytestmark = pytest.mark.unit


def test_all_lists_every_public_name_of_the_package_and_nothing_else() -> None:
    public = {name for name in vars(emos.msgs) if not name.startswith("_")}
    listed = set(emos.msgs.__all__)
    assert len(emos.msgs.__all__) == len(listed), "a name is listed twice in emos.msgs.__all__"
    assert not public - listed, f"public in emos.msgs but missing from its __all__: {sorted(public - listed)}"
    assert not listed - public, f"in emos.msgs.__all__ but not defined there: {sorted(listed - public)}"


def test_star_import_brings_the_message_types_and_the_registry() -> None:
    namespace: dict[str, object] = {}
    exec("from emos.msgs import *", namespace)  # noqa: S102 - a star import is allowed at module level only
    assert namespace["LaserScan"] is emos.msgs.sensor.LaserScan
    assert namespace["resolve"] is emos.msgs.registry.resolve
    assert namespace["Detection2D"] is emos.msgs.intelligence.Detections
