"""``SemanticRouter``: sends each text query to one of several routes (topics).

Vector mode (a ``db_client``): route samples live in a vector-DB collection named
``router_name``; a query goes to the route of its nearest sample when that sample lies within
``maximum_distance``, else to ``default_route``. LLM mode (a ``model_client``): the model picks
the route through a tool call; no valid call means the default route.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, ClassVar

from attrs import define, field

from emos.config import validators as V
from emos.io.topic import Topic
from emos.msgs import intelligence as I
from emos.msgs import std as D

from ..db.spec import DISTANCES
from ..logic.router import LLMRouter, Route, RouteDecision, VectorRouter
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

    @property
    def settings(self) -> RouterSettings:
        return RouterSettings(router_name=self.router_name, distance_func=self.distance_func,
                              maximum_distance=self.maximum_distance)


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
        if (db_client is None) == (model_client is None):
            raise ValueError(f"component {component_name!r}: SemanticRouter needs exactly one of db_client "
                             "(vector mode) or model_client (LLM mode)")
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
        if db_client is not None:
            self._router: VectorRouter | LLMRouter = VectorRouter(routes, db_client, self.config.settings, self.default_route)
        else:
            self._router = LLMRouter(routes, self._chat, self.default_route)
        self.decisions = 0

    def _chat(self, request: Any) -> Any:
        return self.call_model(lambda client: client.chat(request))

    def activate_resources(self) -> None:
        super().activate_resources()
        if isinstance(self._router, VectorRouter):
            self._router.config = self.config.settings
            self._router.initialize()

    def prepare(self, inputs: dict[str, Any], trigger: Topic | None) -> Callable[[], None] | None:
        msg = inputs.get(self.in_topics[0].name)
        query = text_of(msg).strip() if msg is not None else ""
        if not query:
            return None
        return lambda: self._route(query)

    def _route(self, query: str) -> None:
        decision: RouteDecision = self._router.decide(query)
        target = decision.route.routes_to
        if decision.is_default:
            self.get_logger().info("[%s] %r: no route close enough (nearest %r at %s); default route %s",
                                   self.component_name, query, decision.matched_sample, decision.distance, target.name)
        self.publish(target, D.String(data=query))
        self.decisions += 1
        self.health_status.set_healthy()
