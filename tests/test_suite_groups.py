"""The test suite's xdist groups (tests/conftest.py): every unit module that loads the embedding
model in the test process runs in the ``embedder`` group, so that the inner loop (``pytest -m unit
-n 2``, ``--dist loadgroup`` from pyproject.toml) loads torch and sentence-transformers in one worker,
not in both; and the tests of a shared model-server fixture share the worker that started it."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.conftest import SHARED_SERVER_FIXTURES

pytestmark = pytest.mark.unit

TESTS = Path(__file__).resolve().parent
# What makes a test process load the embedding model: the embedder itself, or the embedded Chroma
# store (it embeds with it).
LOADS_THE_MODEL = re.compile(r"SentenceEmbedder\(|ChromaDB\(path=")


def test_every_unit_module_that_loads_the_embedding_model_is_in_the_embedder_group():
    modules = [p for p in TESTS.rglob("test_*.py") if p.name != Path(__file__).name]
    loaders = [p for p in modules if "mark.unit" in (text := p.read_text(encoding="utf-8")) and LOADS_THE_MODEL.search(text)]
    assert len(loaders) >= 5, "the pattern no longer finds the embedding modules"
    missing = [str(p.relative_to(TESTS)) for p in loaders if 'xdist_group("embedder")' not in p.read_text(encoding="utf-8")]
    assert not missing, f"unit modules that load the embedding model outside the 'embedder' xdist group: {missing}"


def test_pytest_distributes_by_group_and_shared_server_fixtures_exist():
    import tomllib

    addopts = tomllib.loads((TESTS.parent / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]["addopts"]
    assert "--dist loadgroup" in addopts, "without it `pytest -n 2` ignores the xdist groups"
    text = "\n".join(p.read_text(encoding="utf-8") for p in TESTS.rglob("*.py"))
    for name in SHARED_SERVER_FIXTURES:
        assert f"def {name}(" in text, f"tests/conftest.py groups the tests of fixture {name!r}, which no longer exists"
