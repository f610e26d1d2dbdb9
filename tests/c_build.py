"""Whether this machine can build the optional C extensions (setup.py): a C compiler and
Python's headers. Where it can, a missing extension is a silent build failure that would leave
every user on the slow path, so the tests of each extension fail instead of skipping."""
from __future__ import annotations

import os
import shutil
import sysconfig


def can_build_c_extensions() -> bool:
    headers = os.path.exists(os.path.join(sysconfig.get_paths()["include"], "Python.h"))
    return bool(shutil.which("cc") or shutil.which("gcc")) and headers
