"""The runs these tests start live in a runtime directory of their own (``$EMOS_RUNTIME_DIR``),
so the runs other tests start meanwhile do not make "which run?" ambiguous, and the tests
decide exactly which runs are live. It is short (``/tmp/ecv...``): a socket path must fit
AF_UNIX's 107 bytes, and pytest's temporary folders are long."""
from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import pytest


@pytest.fixture(scope="module")
def private_runtime():
    root = Path(tempfile.mkdtemp(prefix="ecv", dir="/tmp"))  # mode 0700, ours
    try:
        with pytest.MonkeyPatch.context() as mp:
            mp.setenv("EMOS_RUNTIME_DIR", str(root))
            yield root
    finally:
        shutil.rmtree(root, ignore_errors=True)
