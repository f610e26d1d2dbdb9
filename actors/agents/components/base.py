"""``ModelComponent``: what every agent component shares.

- ``inputs=[...]`` and ``outputs=[...]`` lists whose message types each component declares
  (checked at definition), ``FixedInput`` values read without a subscription, and a ``trigger``
  (a topic, topics, or a period in seconds; default 1.0 s as in EmbodiedAgents);
- a model client (and optionally a DB client) opened off the event loop at activation, so a
  model server that is down at start makes the component report COMPONENT_FAILURE and retry,
  never crash or block its heartbeat;
- every step gathers its inputs on the event loop and hands the model work to a
  :class:`~emos.core.offload.StepWorker` thread: the heartbeat keeps beating while a model thinks;
- publisher preprocessors per output topic (``add_publisher_preprocessor``) and conversion of
  results into the output topic's message type;
- ``additional_model_clients`` and ``change_model_client`` with the request-level failover of
  :mod:`.failover`, and a default ``on_component_fail`` ladder step that reconnects in place.
"""
from __future__ import annotations

import concurrent.futures
import copy
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, TypeVar

from attrs import define, field

from emos.config import validators as V
from emos.config.base import BaseComponentConfig
from emos.core.component import BaseComponent
from emos.core.conventions import check_topics, resolve_config, role_spec
from emos.core.fallbacks import component_fallback
from emos.core.offload import StepWorker
from emos.io.fixed import FixedInput
from emos.io.topic import Topic

from ..errors import GenerationAbandoned, ModelClientError
from ..logic.preprocess import PreprocessorChain
from .convert import OutputConversionError, to_message
from .failover import ModelFailover, is_component_level

T = TypeVar("T")

PRIMARY_CLIENT = "primary"


@define(kw_only=True)
class ModelComponentConfig(BaseComponentConfig):
    """Options shared by every agent component."""

    warmup: bool = field(default=False)
    """LLM/MLLM: send one short chat at activation so the first real request does not pay for
    model loading. (Local models of Vision and SpeechToText are always loaded at activation.)"""

    model_failover_after: int = field(default=2, validator=V.in_range(1, 1000))
    """Consecutive typed client errors on one request before switching to the next of
    ``additional_model_clients`` and re-sending the request being processed."""

    model_retry_backoff: float = field(default=0.1, validator=V.in_range(0.0, 60.0))
    """Seconds between two attempts of the same request on the same client."""

    max_pending: int = field(default=8, validator=V.in_range(1, 10_000))
    """Triggers queued while a model call runs; beyond this the oldest is dropped (counted)."""

    reconnect_period: float = field(default=1.0, validator=V.in_range(0.05, 3600.0))
    """Seconds between attempts to reach a model server that was down at activation."""

    fallback_rate: float = field(default=1.0, validator=V.in_range(1e-9, 1e9))
    """Fallback attempts per second: asking a model server 100 times a second (the default of
    other components) whether it is back helps nobody."""


class _ErrorLog:
    """Logs an error, then at most once per ``period`` seconds with the count of repeats."""

    def __init__(self, logger: Any, period: float = 5.0) -> None:
        self.logger, self.period = logger, period
        self._last: dict[str, float] = {}
        self._count: dict[str, int] = {}

    def __call__(self, key: str, message: str, *args: Any) -> None:
        now = time.monotonic()
        last = self._last.get(key)
        if last is not None and now - last < self.period:
            self._count[key] = self._count.get(key, 0) + 1
            return
        repeats = self._count.pop(key, 0)
        self._last[key] = now
        if repeats:
            # ``message`` is the caller's %-template: format it first, then append the count.
            self.logger.error("%s (and %d more like it in the last %.0f s)", message % args, repeats, self.period)
        else:
            self.logger.error(message, *args)


def _fresh_client(client: Any) -> Any:
    serialize = getattr(client, "serialize", None)
    if callable(serialize):
        from ..clients.base import client_from_serialized

        try:
            return client_from_serialized(serialize())
        except Exception:
            pass
    return copy.deepcopy(client)


class ModelComponent(BaseComponent):
    """Base of LLM, MLLM, Vision, SpeechToText, TextToSpeech, SemanticRouter, MapEncoding..."""

    CONFIG_CLASS: ClassVar[type[ModelComponentConfig]] = ModelComponentConfig
    ALLOWED_INPUTS: ClassVar[tuple[type, ...]] = ()
    ALLOWED_OUTPUTS: ClassVar[tuple[type, ...]] = ()
    #: backlog policy of the model worker: "queue" (answer every trigger) or "latest" (frames)
    PENDING_POLICY: ClassVar[str] = "queue"
    #: whether the component can run without a model client (e.g. Vision with the local classifier)
    MODEL_OPTIONAL: ClassVar[bool] = False
    #: under simulated time, whether a tick is answered only after the steps it triggered (a
    #: detector's frames: perception is part of the loop a lockstep simulator closes). Not for a
    #: model that answers requests: freezing simulated time while a language model thinks would
    #: hide its latency from the robot, which on a real one keeps moving meanwhile.
    STEPS_INSIDE_TICKS: ClassVar[bool] = False

    def __init__(
        self,
        *,
        component_name: str,
        inputs: Sequence[Topic] | None = None,
        outputs: Sequence[Topic] | None = None,
        model_client: Any = None,
        config: ModelComponentConfig | None = None,
        trigger: Topic | Sequence[Topic] | float | None = 1.0,
        db_client: Any = None,
        callback_group: Any = None,
        **kwargs: Any,
    ) -> None:
        # The config and the topics are checked by the rules every component shares
        # (emos.core.conventions); ours are one list per role, typed by ALLOWED_INPUTS/OUTPUTS.
        config = resolve_config(component_name, type(self).__name__, config, self.config_class())
        kind = type(self).__name__
        inputs = check_topics(component_name, kind, "input", list(inputs or []), role_spec(self.ALLOWED_INPUTS))
        outputs = check_topics(component_name, kind, "output", list(outputs or []), role_spec(self.ALLOWED_OUTPUTS))
        self._fixed: dict[str, FixedInput] = {t.name: t for t in inputs if isinstance(t, FixedInput)}
        self._all_inputs: list[Topic] = list(inputs)
        if isinstance(trigger, FixedInput) or (isinstance(trigger, (list, tuple)) and any(isinstance(t, FixedInput) for t in trigger)):
            raise ValueError(f"component {component_name!r}: a FixedInput never changes, so it cannot be a trigger; use a period in seconds")
        super().__init__(component_name=component_name, inputs=[t for t in inputs if not isinstance(t, FixedInput)],
                         outputs=outputs, config=config, trigger=trigger, **kwargs)
        self.config: ModelComponentConfig = config
        if model_client is None and not self.MODEL_OPTIONAL:
            raise ValueError(f"component {component_name!r}: {type(self).__name__} needs a model_client")
        if model_client is not None:
            self._check_client(model_client)
        self._clients: dict[str, Any] = {PRIMARY_CLIENT: model_client} if model_client is not None else {}
        self._active_client = PRIMARY_CLIENT
        self.db_client = db_client
        self._preprocessors: dict[str, PreprocessorChain] = {}
        self._failover = ModelFailover(self)
        self._worker: StepWorker | None = None
        self._client_ready = False
        self._resources_ready = False
        self._client_lock = threading.RLock()
        self._errors = _ErrorLog(self.get_logger())
        if "on_component_fail" not in self.fallbacks and "on_fail" not in self.fallbacks:
            # Default ladder step for an unreachable model server: reconnect in place (a recipe's
            # own on_component_fail / on_fail replaces it). Without it the launcher's default
            # would restart the component every 0.25 s until its restart intensity gives up,
            # which turns a model server that boots after the robot into a dead system.
            from emos.events.action import Action

            self.on_component_fail(action=Action(self.reconnect_model_client))

    # ------------------------------------------------------------------ definition-time checks
    @classmethod
    def config_class(cls) -> type[ModelComponentConfig]:
        return cls.CONFIG_CLASS

    def _check_client(self, client: Any) -> None:
        for attr in ("inference", "check_connection"):
            if not callable(getattr(client, attr, None)):
                raise TypeError(f"component {self.component_name!r}: model_client must be a model client "
                                f"(e.g. OllamaClient), got {type(client).__name__}")

    # ------------------------------------------------------------------ model clients
    @property
    def model_client(self) -> Any:
        return self._clients.get(self._active_client)

    @model_client.setter
    def model_client(self, client: Any) -> None:
        self._check_client(client)
        self._clients[PRIMARY_CLIENT] = client
        self._active_client = PRIMARY_CLIENT
        self._client_ready = False

    @property
    def model_client_name(self) -> str:
        return self._active_client

    @property
    def additional_model_clients(self) -> dict[str, Any]:
        return {k: v for k, v in self._clients.items() if k != PRIMARY_CLIENT}

    @additional_model_clients.setter
    def additional_model_clients(self, clients: Mapping[str, Any]) -> None:
        if not isinstance(clients, Mapping):
            raise TypeError(f"component {self.component_name!r}: additional_model_clients must map names to model clients")
        for name, client in clients.items():
            if not isinstance(name, str) or not name or name == PRIMARY_CLIENT:
                raise ValueError(f"component {self.component_name!r}: additional model client names must be non-empty "
                                 f"strings other than {PRIMARY_CLIENT!r}, got {name!r}")
            self._check_client(client)
        primary = self._clients.get(PRIMARY_CLIENT)
        self._clients = ({PRIMARY_CLIENT: primary} if primary is not None else {}) | dict(clients)

    def change_model_client(self, model_client_name: str) -> bool:
        """Switch to one of ``additional_model_clients`` (or back to ``"primary"``). The new client
        is connected and initialized on first use; returns False for an unknown name."""
        with self._client_lock:
            if model_client_name not in self._clients:
                self.get_logger().error("[%s] change_model_client: no client named %r; known: %s",
                                        self.component_name, model_client_name, sorted(self._clients))
                return False
            if model_client_name == self._active_client:
                return True
            old = self.model_client
            self._active_client = model_client_name
            self._client_ready = False
        # A local model still answering on the old client (switching back from fallback_to_local()
        # to the restarted server) is abandoned, not waited for: the worker asks the new client.
        cancel = getattr(old, "cancel_generation", None)
        if callable(cancel) and cancel():
            self.get_logger().info("[%s] the answer in progress on %r is abandoned", self.component_name, type(old).__name__)
        try:
            if old is not None:
                old.close()
        except Exception as exc:  # closing a dead server's socket may fail; the swap stands
            self.get_logger().debug("[%s] closing the previous client: %s", self.component_name, exc)
        self.get_logger().info("[%s] model client is now %r (%r)", self.component_name, model_client_name, self.model_client)
        return True

    def _ensure_client(self) -> None:
        """Connect and initialize the active client once; raises its typed error if it cannot."""
        client = self.model_client
        if client is None or self._client_ready:
            return
        client.check_connection()
        if getattr(client, "init_on_activation", True):
            client.initialize()
        self._client_ready = True

    def call_model(self, send: Callable[[Any], T], retry_allowed: Callable[[], bool] = lambda: True) -> T:
        """Run ``send(client)`` on the active client with retries and failover (worker thread)."""

        def attempt(client: Any) -> T:
            self._ensure_client()
            used = self.model_client
            try:
                return send(used)
            except GenerationAbandoned:
                # Switched away from ``used`` while it answered: the new client answers instead
                # (unless part of the answer went out already: it is not repeated).
                if self.model_client is used or not retry_allowed():
                    raise
                self.get_logger().info("[%s] asking %r the question the abandoned answer was for", self.component_name, self._active_client)
                self._ensure_client()
                return send(self.model_client)

        return self._failover.call(attempt, retry_allowed=retry_allowed)

    def _on_model_error(self, exc: ModelClientError) -> None:
        self._client_ready = False
        kind = type(exc).__name__
        if is_component_level(exc):
            self.health_status.set_fail_component(component_names=[self.component_name], message=f"{kind}: {exc}")
        else:
            self.health_status.set_fail_algorithm(algorithm_names=[self._active_client], message=f"{kind}: {exc}")
        self._errors(f"model:{kind}", "[%s] model client %r failed: %s", self.component_name, self._active_client, exc)
        self._publish_status()

    def _on_model_success(self) -> None:
        pass

    # ------------------------------------------------------------------ publishing
    def add_publisher_preprocessor(self, topic: Topic | str, function: Callable[[Any], Any]) -> None:
        """Apply ``function`` to every output before it is published on ``topic``; returning
        None publishes nothing. Several preprocessors on one topic run in order."""
        name = topic.name if isinstance(topic, Topic) else Topic(name=topic, msg_type="String").name
        if name not in {t.name for t in self.out_topics}:
            raise ValueError(f"component {self.component_name!r}: {name!r} is not an output; outputs are "
                             f"{[t.name for t in self.out_topics]}")
        self._preprocessors.setdefault(name, PreprocessorChain(name)).add(function)

    def publish_output(self, topic: Topic, value: Any) -> bool:
        """Preprocess, convert and publish one output; False if a preprocessor dropped it."""
        chain = self._preprocessors.get(topic.name)
        if chain is not None:
            try:
                value = chain(value)
            except Exception as exc:
                self._errors(f"pre:{topic.name}", "[%s] publisher preprocessor of %r raised %s: %s",
                             self.component_name, topic.name, type(exc).__name__, exc)
                return False
            if value is None:
                return False
        self.publish(topic, to_message(topic.msg_type, value, topic.name))
        return True

    def publish_all(self, value: Any, types: tuple[type, ...] | None = None) -> int:
        """Publish ``value`` on every output (of ``types``, if given); returns how many went out.
        A conversion failure on one topic is reported and does not stop the others."""
        sent = 0
        for topic in self.out_topics:
            if types is not None and not issubclass(topic.msg_type, types):
                continue
            try:
                sent += self.publish_output(topic, value)
            except OutputConversionError as exc:
                self.health_status.set_fail_algorithm(algorithm_names=[topic.name], message=str(exc))
                self._errors(f"conv:{topic.name}", "[%s] %s", self.component_name, exc)
        return sent

    def _publish_status(self) -> None:
        node = self._node
        if node is not None:
            node.publish_status()

    # ------------------------------------------------------------------ inputs
    @staticmethod
    def variable_name(topic: Topic) -> str:
        """The name a template uses for a topic: its name without the leading '/'."""
        return topic.name.lstrip("/")

    def gather_inputs(self, msg: Any = None, topic: Topic | None = None) -> dict[str, Any]:
        """Latest message of every input (fixed inputs included), by topic name; the trigger's
        own message is the one that triggered this step."""
        out: dict[str, Any] = {}
        for t in self._all_inputs:
            if isinstance(t, FixedInput):
                out[t.name] = t.message
            elif topic is not None and t.name == topic.name and msg is not None:
                out[t.name] = msg
            else:
                value = self.get_input(t)
                if value is not None:
                    out[t.name] = value
        return out

    @property
    def input_topics(self) -> list[Topic]:
        """Every input in declaration order, fixed ones included."""
        return list(self._all_inputs)

    # ------------------------------------------------------------------ lifecycle
    def custom_on_activate(self) -> concurrent.futures.Future[Any]:
        """Opens the resources in the worker thread. The component is ACTIVE once its own
        resources (the DB, local models: an embedding model takes 17-85 s to load on a busy
        machine) are open or have failed, so it can serve what it is sent; the model server is
        not waited for (a dead server must not hold up the robot: its ladder reconnects)."""
        self._worker = StepWorker(self.component_name, self.PENDING_POLICY, self.config.max_pending,
                                  on_error=self._on_job_error)
        self._worker.start()
        if self.STEPS_INSIDE_TICKS and self._node is not None:
            self._node.hold_ticks_for(self._worker)
        self._client_ready = False
        ready: concurrent.futures.Future[Any] = concurrent.futures.Future()
        if not self._worker.submit(lambda: self._activate_in_worker(ready)):
            ready.set_result(None)
        if self.model_client is not None:
            self.create_timer(self.config.reconnect_period, self._reconnect_tick)
        return ready

    def _activate_in_worker(self, ready: concurrent.futures.Future[Any] | None = None) -> None:
        """Open the DB and the model client without blocking the loop; report, don't crash."""
        self._resources_ready = False
        try:
            opened = self.ensure_resources()
        finally:
            if ready is not None and not ready.done():
                ready.set_result(None)  # open or failed (and reported): the node goes ACTIVE
        if not opened:
            self._publish_status()
            return
        if self.model_client is None:
            return
        try:
            self._ensure_client()
            if self.config.warmup:
                self.warmup()
        except ModelClientError as exc:
            self._on_model_error(exc)
            return
        self._clear_model_failure()

    def activate_resources(self) -> None:
        """Open heavy resources (DB, local models); runs in the worker thread at activation.
        Raising reports COMPONENT_FAILURE; the component lives on and ``resources_ready`` stays
        False until a later :meth:`ensure_resources` succeeds."""
        if self.db_client is not None:
            self.db_client.initialize()

    def ensure_resources(self) -> bool:
        """Worker thread: (re)open the resources if activation could not; False if still failing."""
        if self._resources_ready:
            return True
        try:
            self.activate_resources()
        except Exception as exc:
            self.health_status.set_fail_component(component_names=[self.component_name], message=f"{type(exc).__name__}: {exc}")
            self._errors("activate", "[%s] cannot open its resources: %s", self.component_name, exc)
            return False
        self._resources_ready = True
        return True

    def warmup(self) -> None:
        """One throw-away request (subclasses that support it override this)."""

    def custom_on_deactivate(self) -> None:
        if self._worker is not None:
            if self._node is not None:
                self._node.release_ticks_from(self._worker)
            self._worker.stop(timeout=5.0)
            self._worker = None
        for client in self._clients.values():
            try:
                client.close()
            except Exception as exc:
                self.get_logger().debug("[%s] closing a client: %s", self.component_name, exc)
        self.release_resources()
        self._resources_ready = False

    def release_resources(self) -> None:
        if self.db_client is not None:
            try:
                self.db_client.deinitialize()
            except Exception as exc:
                self.get_logger().warning("[%s] closing the DB client: %s", self.component_name, exc)

    # ------------------------------------------------------------------ steps
    def _execution_step(self, msg: Any = None, topic: Topic | None = None, **kwargs: Any) -> None:
        inputs = self.gather_inputs(msg, topic)
        missing = self.missing_inputs(inputs)
        if missing:
            self.health_status.set_fail_system(topic_names=missing, message=f"no data yet on {', '.join(missing)}")
            return
        job = self.prepare(inputs, topic)
        if job is None:
            return
        worker = self._worker
        if worker is None or not worker.submit(lambda: self._run_job(job), step=True):
            self._errors("worker", "[%s] step skipped: the model worker is not running", self.component_name)

    def missing_inputs(self, inputs: Mapping[str, Any]) -> list[str]:
        """Inputs the step cannot do without (default: none)."""
        return []

    def prepare(self, inputs: dict[str, Any], trigger: Topic | None) -> Callable[[], None] | None:
        """On the event loop: turn the gathered inputs into a job for the worker (or None)."""
        raise NotImplementedError

    def _run_job(self, job: Callable[[], None]) -> None:
        if not self.ensure_resources():
            self._publish_status()
            return
        try:
            job()
        except ModelClientError as exc:
            # Retries and swaps are exhausted: the request is given up, the status says why.
            self._errors("giveup", "[%s] request given up after retries and fallbacks: %s", self.component_name, exc)
        self._publish_status()

    def _reconnect_tick(self) -> None:
        """On the loop, every ``reconnect_period``: if the model server was unreachable, try again."""
        worker = self._worker
        if self.model_client is None or self._client_ready or worker is None or worker.busy:
            return
        worker.submit(self._reconnect_in_worker)

    @component_fallback
    def reconnect_model_client(self) -> bool:
        """Fallback action: ask the worker to reach the model server (and reopen the DB) again.
        Returns at once (it runs on the event loop); True when the component is ready."""
        worker = self._worker
        if worker is not None and not worker.busy:
            if not self._resources_ready:

                def reopen() -> None:  # worker thread
                    if self.ensure_resources():
                        self._publish_status()

                worker.submit(reopen)
            if self.model_client is not None and not self._client_ready:
                worker.submit(self._reconnect_in_worker)
        return self._resources_ready and (self.model_client is None or self._client_ready)

    def _reconnect_in_worker(self) -> None:
        if self._client_ready:
            return
        try:
            self._ensure_client()
        except ModelClientError as exc:
            self._on_model_error(exc)
            return
        self.get_logger().info("[%s] model client %r is reachable", self.component_name, self._active_client)
        self._clear_model_failure()

    def _clear_model_failure(self) -> None:
        """The model client works (again): clear a failure it caused, but not a newer report
        about missing inputs that a step made meanwhile."""
        if not self.health_status.is_system_fail:
            self.health_status.set_healthy()
        self._publish_status()

    def _on_job_error(self, exc: BaseException) -> None:
        if isinstance(exc, GenerationAbandoned):  # a client switch, not a failure: nothing to recover
            self.get_logger().info("[%s] %s", self.component_name, exc)
            return
        self.health_status.set_fail_component(component_names=[self.component_name], message=f"{type(exc).__name__}: {exc}")
        self._errors(f"job:{type(exc).__name__}", "[%s] step failed: %s: %s", self.component_name, type(exc).__name__, exc)
        self._publish_status()

    # ------------------------------------------------------------------ copies (threaded restarts)
    def __deepcopy__(self, memo: dict) -> ModelComponent:
        """A pristine copy for a restart in threaded mode: model clients are rebuilt from their
        serialized form (live sockets and locks are not copied), runtime state starts empty,
        and parts that cannot be copied (compiled templates, registered tools) are shared:
        they are not changed by running."""
        new = type(self).__new__(type(self))
        memo[id(self)] = new
        for key, value in self.__dict__.items():
            if key == "_clients":
                new.__dict__[key] = {name: _fresh_client(c) for name, c in value.items()}
            elif key in ("_node", "_worker"):
                new.__dict__[key] = None
            elif key == "_client_lock":
                new.__dict__[key] = threading.RLock()
            else:
                try:
                    new.__dict__[key] = copy.deepcopy(value, memo)
                except Exception:
                    new.__dict__[key] = value
        new._client_ready = False
        new._resources_ready = False
        return new

    @property
    def dropped_triggers(self) -> int:
        return self._worker.dropped if self._worker is not None else 0
