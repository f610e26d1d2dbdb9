"""Model fallbacks: retry the current model client, hot-swap to a backup, give up.

Written as an interim hook while the events/fallbacks ladders were built on another branch; they
have landed since. The ladders (``on_component_fail`` / ``on_algorithm_fail`` with actions such as
``Action(method=llm.change_model_client, args=("backup",))``) act after a failure was reported;
this policy acts inside the request: after ``model_failover_after`` consecutive typed client
errors it calls ``change_model_client`` with the next of ``additional_model_clients`` and re-sends
the request being processed, so that request is answered instead of lost.
"""
from __future__ import annotations

import time
from typing import Any, Callable, TypeVar

from ..errors import ModelClientError, ModelConnectionError, ModelTimeoutError

T = TypeVar("T")


def is_component_level(exc: ModelClientError) -> bool:
    """Unreachable or silent server: the component cannot work (COMPONENT_FAILURE). Anything
    else (an HTTP error status, a malformed answer, a missing model) means the server runs but
    the model step failed (ALGORITHM_FAILURE)."""
    return isinstance(exc, (ModelConnectionError, ModelTimeoutError))


class ModelFailover:
    """Runs one request against the component's current client with retries and swaps."""

    def __init__(self, component: Any) -> None:
        self.component = component

    def call(self, send: Callable[[Any], T], *, retry_allowed: Callable[[], bool] = lambda: True) -> T:
        comp = self.component
        after = comp.config.model_failover_after
        tried: set[str] = {comp.model_client_name}
        failures = 0
        while True:
            client = comp.model_client
            try:
                result = send(client)
            except ModelClientError as exc:
                failures += 1
                comp._on_model_error(exc)
                if not retry_allowed():  # e.g. part of a stream already went out: re-sending would repeat it
                    raise
                if failures < after:
                    time.sleep(comp.config.model_retry_backoff)
                    continue
                backup = next((name for name in comp.additional_model_clients if name not in tried), None)
                if backup is None:
                    raise
                tried.add(backup)
                comp.get_logger().warning("[%s] %d failure(s) of model client %r (%s); switching to %r",
                                          comp.component_name, failures, comp.model_client_name, exc, backup)
                comp.change_model_client(backup)
                failures = 0
                continue
            comp._on_model_success()
            return result
