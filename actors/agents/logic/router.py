"""SemanticRouter decisions.

Vector mode: every route's samples are stored in a vector-DB collection named ``router_name``;
a query is embedded and its nearest sample decides the route if it lies within
``maximum_distance``, else the default route. LLM mode: each route becomes one tool and the
model's tool call decides; no (valid) call means the default route.
"""
from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from typing import Any

import attrs

from emos.config import validators as V

from ..db.spec import DISTANCES
from ..types import ChatMessage, ChatRequest, ChatResponse, ToolSpec


def _route_target_name(value: Any) -> str:
    name = value if isinstance(value, str) else getattr(value, "name", None)
    if not isinstance(name, str) or not name:
        raise TypeError(f"Route.routes_to: expected a Topic, an Action or a name, got {type(value).__name__}")
    return name


def _samples(value: Sequence[str]) -> list[str]:
    if isinstance(value, str):
        raise TypeError("Route.samples: expected a list of example queries, got one str")
    samples = list(value)
    if not samples or not all(isinstance(s, str) and s.strip() for s in samples):
        raise ValueError("Route.samples: expected a non-empty list of non-empty strings")
    return samples


@attrs.define
class Route:
    """Where matching queries go (``routes_to``: a Topic, an Action or a name) and examples."""

    routes_to: Any = attrs.field()
    samples: list[str] = attrs.field(converter=_samples)

    @routes_to.validator
    def _check(self, attribute, value) -> None:
        _route_target_name(value)

    @property
    def name(self) -> str:
        return _route_target_name(self.routes_to)


#: Default ``maximum_distance`` per distance function. All three equal a cosine similarity of
#: 0.25 for L2-normalized embeddings (squared L2 = 2 * (1 - cos); ip and cosine = 1 - cos).
#: Chosen on principle (a clearly related query), then checked on the labeled set in
#: emos.actors.agents.data: 0.4 squared-L2 (cos 0.8) sent most paraphrases to the default route.
DEFAULT_MAXIMUM_DISTANCE = {"l2": 1.5, "ip": 0.75, "cosine": 0.75}


@attrs.define(kw_only=True)
class SemanticRouterConfig:
    """``maximum_distance`` is in the units of ``distance_func`` (None: the default for it)."""

    router_name: str = attrs.field(validator=attrs.validators.and_(attrs.validators.instance_of(str),
                                                                   attrs.validators.min_len(1)))
    distance_func: str = attrs.field(default="l2", validator=attrs.validators.in_(DISTANCES))
    maximum_distance: float | None = attrs.field(default=None, validator=V.positive_or_none)

    @property
    def effective_maximum_distance(self) -> float:
        if self.maximum_distance is not None:
            return float(self.maximum_distance)
        return DEFAULT_MAXIMUM_DISTANCE[self.distance_func]


@attrs.frozen
class RouteDecision:
    route: Route
    distance: float | None = None     # vector mode: distance to the nearest sample
    matched_sample: str | None = None
    is_default: bool = False
    #: why the default route was taken, in words of the mode that decided (a vector router has a
    #: nearest sample and a distance, a model has only its tool calls); "" for a matched route
    reason: str = ""


def _check_routes(routes: Sequence[Route], default_route: Route | None) -> list[Route]:
    routes = list(routes)
    if not routes or not all(isinstance(r, Route) for r in routes):
        raise ValueError("routes: expected a non-empty list of Route")
    names = [r.name for r in routes]
    if len(set(names)) != len(names):
        raise ValueError(f"routes: two routes lead to the same target: {names}")
    if default_route is not None and default_route.name not in names:
        raise ValueError(f"default_route {default_route.name!r} is not one of the routes {names}")
    return routes


class VectorRouter:
    """Nearest-sample routing over a ChromaClient (or anything with upsert/query)."""

    def __init__(self, routes: Sequence[Route], db_client: Any, config: SemanticRouterConfig,
                 default_route: Route | None = None) -> None:
        self.routes = _check_routes(routes, default_route)
        self.default_route = default_route or self.routes[0]
        self.config = config
        self.db = db_client
        self._by_name = {r.name: r for r in self.routes}

    def initialize(self) -> None:
        """(Re)store every route sample. Ids are deterministic, so restarts do not duplicate."""
        self.db.reset(self.config.router_name)
        documents, metadatas, ids = [], [], []
        for route in self.routes:
            for i, sample in enumerate(route.samples):
                documents.append(sample)
                metadatas.append({"route_name": route.name})
                ids.append(f"{route.name}:{i}")
        self.db.upsert(self.config.router_name, documents, metadatas=metadatas, ids=ids,
                       distance_func=self.config.distance_func)

    def decide(self, query: str) -> RouteDecision:
        if not isinstance(query, str) or not query.strip():
            raise ValueError("route query: expected a non-empty string")
        hits = self.db.query(self.config.router_name, query, n_results=1, distance_func=self.config.distance_func)
        if not hits:
            raise RuntimeError(f"router collection {self.config.router_name!r} is empty: call initialize() first")
        hit = hits[0]
        route_name = hit.metadata.get("route_name")
        route = self._by_name.get(route_name)
        if route is None:
            # A collection written by another router of the same name (a stale store).
            return RouteDecision(self.default_route, hit.distance, hit.document, is_default=True,
                                 reason=f"the nearest sample {hit.document!r} belongs to no route of this router "
                                        f"({route_name!r})")
        limit = self.config.effective_maximum_distance
        if hit.distance > limit:
            return RouteDecision(self.default_route, hit.distance, hit.document, is_default=True,
                                 reason=f"no route close enough (nearest sample {hit.document!r} at "
                                        f"{self.config.distance_func} distance {hit.distance:.3f} > {limit:g})")
        return RouteDecision(route, hit.distance, hit.document)


def _tool_name(route_name: str) -> str:
    # OpenAI tool names allow [a-zA-Z0-9_-] only (max 64); topic names may contain '/'.
    return ("route_to_" + re.sub(r"[^a-zA-Z0-9_-]", "_", route_name))[:64]


class LLMRouter:
    """Lets a chat model pick the route: one tool per route, the tool call is the decision."""

    def __init__(self, routes: Sequence[Route], chat: Callable[[ChatRequest], ChatResponse],
                 default_route: Route | None = None, system_prompt: str | None = None) -> None:
        self.routes = _check_routes(routes, default_route)
        self.default_route = default_route or self.routes[0]
        self.chat = chat
        self._by_tool = {_tool_name(r.name): r for r in self.routes}
        if len(self._by_tool) != len(self.routes):
            raise ValueError("routes: two route names map to the same tool name")
        self.tools = [
            ToolSpec(name=tool, description=f"Send the query to {route.name!r}. Use it for queries like: "
                     + "; ".join(route.samples),
                     parameters={"type": "object", "properties": {}})
            for tool, route in self._by_tool.items()]
        self.system_prompt = system_prompt or (
            "You route user queries. Call exactly one of the tools: the one whose examples match "
            "the intent of the query best.")

    def decide(self, query: str) -> RouteDecision:
        if not isinstance(query, str) or not query.strip():
            raise ValueError("route query: expected a non-empty string")
        request = ChatRequest(messages=[ChatMessage(role="system", content=self.system_prompt),
                                        ChatMessage(role="user", content=query)], tools=self.tools)
        response = self.chat(request)
        calls = [call.name for call in response.message.tool_calls]
        for name in calls:
            route = self._by_tool.get(name)
            if route is not None:
                return RouteDecision(route)
        # The names come from the model: shortened, so a rambling answer cannot flood the log.
        reason = (f"the model called no route tool (it called {', '.join(repr(n[:64]) for n in calls[:4])})" if calls
                  else "the model called no route tool")
        return RouteDecision(self.default_route, is_default=True, reason=reason)
