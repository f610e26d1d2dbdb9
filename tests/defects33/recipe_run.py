"""Running a recipe file of recipes/ as a user would (``emos run recipes/X.py``), from a test."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from emos.transport.context import RunContext
from tests.runtime.helpers import _STARTED, REPO, SystemUnderTest


class RecipeRun(SystemUnderTest):
    """``emos run RECIPE`` in its own process, with the helpers of SystemUnderTest.

    ``home``: the run's $HOME (recipes write to ``~/...``); the working directory is a folder
    of its own beside it (a cwd holding ``emos/`` would shadow the package)."""

    def __init__(self, tmp_path: Path, recipe: Path, home: Path, env: dict | None = None):
        _STARTED.append(self)
        self.script = recipe
        work = tmp_path / "work"
        work.mkdir(exist_ok=True)
        home.mkdir(parents=True, exist_ok=True)
        self.log_path = tmp_path / "system.log"
        self._log = open(self.log_path, "wb")  # noqa: SIM115 - closed by stop/wait_exit/kill_all
        full_env = {**os.environ, "HOME": str(home), "PYTHONPATH": str(REPO), **(env or {})}
        self.proc = subprocess.Popen([sys.executable, "-m", "emos", "run", str(recipe)], stdout=self._log,
                                     stderr=subprocess.STDOUT, env=full_env, cwd=work)
        self.run_dir = None
        self.ctx: RunContext | None = None
        self.rpc = None

    def run_id(self) -> str:
        assert self.run_dir is not None, "wait_up() first"
        return self.run_dir.name
