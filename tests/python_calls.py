"""How much of a call runs in the interpreter, counted rather than timed: the C fast paths' tests
check that they take Python out of a hot path without depending on the machine's speed or load."""
from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any


def python_calls(fn: Callable[..., Any], *args: Any) -> int:
    """How many Python functions ``fn(*args)`` entered (C calls not counted; ``fn`` itself not)."""
    calls = 0

    def count(frame: Any, event: str, arg: Any) -> None:
        nonlocal calls
        if event == "call":
            calls += 1

    sys.setprofile(count)
    try:
        fn(*args)
    finally:
        sys.setprofile(None)
    return calls - 1
