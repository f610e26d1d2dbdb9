"""Model fallbacks: retry the current model client, hot-swap to a backup, give up.

Written as an interim hook while the events/fallbacks ladders were built on another branch; they
have landed since. The ladders (``on_component_fail`` / ``on_algorithm_fail`` with actions such as
``Action(method=llm.change_model_client, args=("backup",))``) act after a failure was reported;
this policy acts inside the request: after ``model_failover_after`` consecutive typed client
errors it calls ``change_model_client`` with the next of ``additional_model_clients`` and re-sends
the request being processed, so that request is answered instead of lost.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from emos.core.retry import Backoff, retry

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
        tried: set[str] = {comp.model_client_name}
        while True:
            client = comp.model_client

            def attempt(client: Any = client) -> T:  # this loop's client, bound now
                try:
                    return send(client)
                except ModelClientError as exc:
                    comp._on_model_error(exc)
                    raise

            after = comp.config.model_failover_after
            try:
                # The same client up to ``model_failover_after`` times, ``model_retry_backoff``
                # apart; never again once retry_allowed() says no (e.g. part of a stream already
                # went out: re-sending would repeat it).
                result = retry(attempt, Backoff(attempts=after, base=comp.config.model_retry_backoff, factor=1.0),
                               retry_on=ModelClientError, retry_if=lambda exc: retry_allowed())
            except ModelClientError as exc:
                if not retry_allowed():
                    raise
                backup = next((name for name in comp.additional_model_clients if name not in tried), None)
                if backup is None:
                    raise
                tried.add(backup)
                comp.get_logger().warning("[%s] %d failure(s) of model client %r (%s); switching to %r",
                                          comp.component_name, after, comp.model_client_name, exc, backup)
                comp.change_model_client(backup)
                continue
            comp._on_model_success()
            return result
