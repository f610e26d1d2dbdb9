"""One exception tree: every exception class EMOS defines derives from ``EmosError`` (issue 32).

The walk imports every module of the installed packages (a module whose optional dependency is
missing here is skipped, and named in the skip reason), collects the exception classes each
defines, and fails on one outside the tree or on two classes with the same name (one concept,
one class: ``MessageTooLarge`` was once defined twice).
"""
from __future__ import annotations

import importlib
import inspect
import pkgutil
from collections import defaultdict

import pytest

from emos.errors import ConfigError, EmosError, TransportError

pytestmark = pytest.mark.unit

ROOTS = ("emos", "emos.actors", "emos.supervisor", "emos.chaos", "emos.tools")


def _is_optional_dependency(exc: ImportError) -> bool:
    """A missing third-party module (an extra not installed), not a broken EMOS import."""
    missing = getattr(exc, "name", None) or ""
    return bool(missing) and missing.split(".")[0] != "emos"


def _walk() -> tuple[list[type], list[str]]:
    classes: list[type] = []
    skipped: list[str] = []
    for root in ROOTS:
        package = importlib.import_module(root)
        for info in pkgutil.walk_packages(package.__path__, root + "."):
            leaf = info.name.rsplit(".", 1)[-1]
            if leaf == "__main__" or leaf.endswith("_system"):
                continue  # a program to run (the *_system benchmarks bring a system up on import)
            try:
                module = importlib.import_module(info.name)
            except ImportError as exc:
                if not _is_optional_dependency(exc):
                    raise
                skipped.append(f"{info.name} ({exc.name})")
                continue
            for obj in vars(module).values():
                if inspect.isclass(obj) and issubclass(obj, BaseException) and obj.__module__ == info.name:
                    classes.append(obj)
    return classes, skipped


@pytest.fixture(scope="module")
def exception_classes() -> list[type]:
    classes, _skipped = _walk()
    return classes


def _where(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def test_every_emos_exception_derives_from_emos_error(exception_classes: list[type]) -> None:
    assert len(exception_classes) > 50  # the walk found the packages' modules
    outside = sorted(_where(c) for c in exception_classes if not issubclass(c, EmosError))
    assert not outside, f"exception classes outside the EmosError tree: {outside}"


def test_no_two_exception_classes_share_a_name(exception_classes: list[type]) -> None:
    by_name: dict[str, list[str]] = defaultdict(list)
    for cls in exception_classes:
        by_name[cls.__name__].append(_where(cls))
    twice = {name: where for name, where in by_name.items() if len(where) > 1}
    assert not twice, f"one concept, one class; defined more than once: {twice}"


def test_built_in_bases_are_kept_for_existing_callers() -> None:
    # Callers written before the tree catch the built-in base; the tree must not take it away.
    from emos.config import ConfigError as LoaderConfigError
    from emos.transport import MessageTooLarge, ring

    assert LoaderConfigError is ConfigError and issubclass(ConfigError, ValueError)
    assert ring.MessageTooLarge is MessageTooLarge
    assert issubclass(MessageTooLarge, ValueError) and issubclass(MessageTooLarge, ring.RingError)
    assert issubclass(ring.RingError, RuntimeError) and issubclass(ring.RingError, TransportError)
    with pytest.raises(ValueError, match="exceeds"):
        raise MessageTooLarge("a message of 9 B exceeds the limit of 8 B")


def test_emos_error_is_exported_from_the_package() -> None:
    import emos

    assert emos.EmosError is EmosError
    assert "EmosError" in emos.__all__
