"""Publisher preprocessor chains: functions applied to a component's output before it is
published on one topic. A function returning None means "publish nothing this time"."""
from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any


class PreprocessorChain:
    def __init__(self, topic: str = "output") -> None:
        self.topic = topic
        self._functions: list[Callable[[Any], Any]] = []

    def add(self, function: Callable[[Any], Any]) -> None:
        """Append a one-argument callable (checked now, not at the first publish)."""
        if not callable(function):
            raise TypeError(f"preprocessor for {self.topic!r}: expected a callable, got {type(function).__name__}")
        try:
            inspect.signature(function).bind(None)
        except TypeError:
            raise TypeError(f"preprocessor {getattr(function, '__name__', function)!r} for {self.topic!r} "
                            "must accept exactly one positional argument (the output)") from None
        except ValueError:  # builtins without a signature: accept, they fail loudly if wrong
            pass
        self._functions.append(function)

    def __call__(self, output: Any) -> Any | None:
        for function in self._functions:
            output = function(output)
            if output is None:
                return None
        return output

    def __len__(self) -> int:
        return len(self._functions)
