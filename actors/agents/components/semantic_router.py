"""``SemanticRouter``: sends each text query to one of several routes (topics).

Vector mode (a ``db_client``): route samples live in a vector-DB collection named
``router_name``; a classifier fitted on the samples and the routes' descriptions picks the route
(``scoring="learned"``, see logic/router.py), or the nearest sample does (``scoring="nearest"``);
in both, a query whose nearest sample lies beyond ``maximum_distance`` goes to ``default_route``.
LLM mode (a ``model_client``): the model picks the route through a tool call; no valid call
means the default route. Hybrid mode (both): vector routing, and the model decides the queries
whose best two routes score within ``llm_margin`` of each other.

Vector mode loads the embedding model and stores the route samples at activation, in the model
worker, before any query: a query that arrives meanwhile waits in the worker's queue and is
routed once the router can serve. While it loads, the status is GENERAL with a message that says
so (not HEALTHY: it cannot route yet). A query that is not routed (the queue overflowed, the store
could not be opened) is logged, rate-limited, with a count naming the component and topic.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, ClassVar

from attrs import define, field

from emos.config import validators as V
from emos.io.topic import Topic
from emos.msgs import intelligence as I
from emos.msgs import std as D
from emos.ratelimit import RateLimitedLog

from ..db.spec import DISTANCES
from ..logic.router import SCORINGS, HybridRouter, LLMRouter, Route, RouteDecision, VectorRouter
from ..logic.router import SemanticRouterConfig as RouterSettings
from .base import ModelComponent, ModelComponentConfig
from .convert import text_of

__all__ = ["SemanticRouter", "SemanticRouterConfig", "Route"]


@define(kw_only=True)
class SemanticRouterConfig(ModelComponentConfig):
    router_name: str = field(default="router", validator=lambda i, a, v: _name(v))
    distance_func: str = field(default="l2", validator=V.in_(DISTANCES))
    #: in the units of distance_func; None = the default for it (see logic.router)
    maximum_distance: float | None = field(default=None, validator=V.positive_or_none)
    #: "learned" (a classifier on the samples and descriptions) or "nearest" (EmbodiedAgents' rule)
    scoring: str = field(default="learned", validator=V.in_(SCORINGS))
    #: hybrid mode: vector decisions with a smaller probability margin are left to the model
    llm_margin: float = field(default=RouterSettings.__attrs_attrs__.llm_margin.default,
                              validator=V.in_range(0.0, 1.0))

    @property
    def settings(self) -> RouterSettings:
        return RouterSettings(router_name=self.router_name, distance_func=self.distance_func,
                              maximum_distance=self.maximum_distance, scoring=self.scoring,
                              llm_margin=self.llm_margin)


def _name(value: Any) -> None:
    if not isinstance(value, str) or len(value) < 3:
        raise ValueError(f"SemanticRouterConfig.router_name: expected a collection name of 3+ characters, got {value!r}")


class SemanticRouter(ModelComponent):
    CONFIG_CLASS: ClassVar[type] = SemanticRouterConfig
    ALLOWED_INPUTS: ClassVar[tuple[type, ...]] = (D.String, I.StreamingString)
    ALLOWED_OUTPUTS: ClassVar[tuple[type, ...]] = (D.String,)
    MODEL_OPTIONAL: ClassVar[bool] = True

    def __init__(self, *, inputs: list[Topic], routes: Sequence[Route], default_route: Route | None = None,
                 config: SemanticRouterConfig | None = None, db_client: Any = None, model_client: Any = None,
                 component_name: str, **kwargs: Any) -> None:
        if db_client is None and model_client is None:
            raise ValueError(f"component {component_name!r}: SemanticRouter got neither db_client nor model_client: give "
                             "exactly one of db_client (vector mode) or model_client (LLM mode), or both (hybrid mode: "
                             "the model decides close calls)")
        routes = list(routes)
        if not routes or not all(isinstance(r, Route) for r in routes):
            raise ValueError(f"component {component_name!r}: routes must be a non-empty list of Route")
        for r in routes:
            if not isinstance(r.routes_to, Topic):
                raise TypeError(f"component {component_name!r}: Route to {r.name!r} must lead to a Topic "
                                "(routes to Actions need the events module)")
        inputs = list(inputs)
        if len(inputs) != 1:
            raise ValueError(f"component {component_name!r}: SemanticRouter takes exactly one query input, got {len(inputs)}")
        outputs = list({r.routes_to.name: r.routes_to for r in routes}.values())
        super().__init__(inputs=inputs, outputs=outputs, model_client=model_client, config=config, db_client=db_client,
                         trigger=inputs[0], component_name=component_name, **kwargs)
        self.config: SemanticRouterConfig
        self.routes = routes
        self.default_route = default_route or routes[0]
        # Built now so bad routes (duplicates, an unknown default) fail in the recipe line.
        self._router: VectorRouter | LLMRouter | HybridRouter
        if db_client is not None:
            self._router = VectorRouter(routes, db_client, self.config.settings, self.default_route)
            if model_client is not None:
                self._router = HybridRouter(self._router, LLMRouter(routes, self._chat, self.default_route))
        else:
            self._router = LLMRouter(routes, self._chat, self.default_route)
        self.decisions = 0
        self.dropped_queries = 0  # queries that were not routed (each one logged, rate-limited)
        self._drops = RateLimitedLog(self.get_logger(), interval=5.0)

    def _chat(self, request: Any) -> Any:
        return self.call_model(lambda client: client.chat(request))

    def activate_resources(self) -> None:
        vector = isinstance(self._router, (VectorRouter, HybridRouter))
        loading = f"{self.component_name}: loading the embedding model and the route samples"
        if vector:
            # Not ready until the model is loaded (17-85 s on a loaded 2-core machine): say so,
            # rather than HEALTHY while queries wait.
            self.health_status.set_general(loading)
            self._publish_status()
        super().activate_resources()  # opens the DB client, which loads its embedding model
        if isinstance(self._router, (VectorRouter, HybridRouter)):
            self._router.config = self.config.settings
            self._router.initialize()
        if vector and self.health_status.message == loading:  # ready (a newer report, if any, stays)
            self.health_status.set_healthy()
            self._publish_status()

    # ------------------------------------------------------------------ queries not routed
    def _dropped(self, count: int, why: str) -> None:
        self.dropped_queries += count
        topic = self.in_topics[0].name
        self._drops.warning(("drop", why), "[%s] %d query(ies) on %s not routed: %s (%d in all)",
                            self.component_name, count, topic, why, self.dropped_queries)

    def _execution_step(self, msg: Any = None, topic: Topic | None = None, **kwargs: Any) -> None:
        worker = self._worker
        before = worker.dropped if worker is not None else 0
        super()._execution_step(msg, topic)
        if worker is not None and worker.dropped > before:
            self._dropped(worker.dropped - before, f"more than max_pending={self.config.max_pending} queries waiting; "
                                                   "the oldest was dropped")

    def _run_job(self, job: Callable[[], None]) -> None:
        if not self.ensure_resources():
            self._dropped(1, "its resources (DB, embedding model) cannot be opened; the status says why")
            self._publish_status()
            return
        super()._run_job(job)

    def prepare(self, inputs: dict[str, Any], trigger: Topic | None) -> Callable[[], None] | None:
        msg = inputs.get(self.in_topics[0].name)
        query = text_of(msg).strip() if msg is not None else ""
        if not query:
            self._drops.warning("empty", "[%s] ignoring an empty query on %s", self.component_name, self.in_topics[0].name)
            return None
        return lambda: self._route(query)

    def _route(self, query: str) -> None:
        decision: RouteDecision = self._router.decide(query)
        target = decision.route.routes_to
        if decision.is_default:
            self.get_logger().info("[%s] %r: %s; default route %s", self.component_name, query, decision.reason, target.name)
        self.publish(target, D.String(data=query))
        self.decisions += 1
        self.health_status.set_healthy()
