"""SemanticRouter decisions.

Vector mode: every route's samples are stored in a vector-DB collection named ``router_name``.
With ``scoring="learned"`` (the default) a linear classifier (multinomial logistic regression,
L2-regularized, classes balanced) is fitted at ``initialize`` on the embeddings of the route
samples and of the phrases of each route's ``description``; a query goes to the route it gives
the highest probability. With ``scoring="nearest"`` (EmbodiedAgents' rule) the route of the
nearest sample wins. Either way a query whose nearest sample lies beyond ``maximum_distance``
(default: cosine similarity 0.25, see DEFAULT_MAXIMUM_DISTANCE) goes to the default route; with
``scoring="learned"`` the phrases of the routes' descriptions count as samples for that bound too
(what a route declares it covers is not "far" from it; docs/local-models.md).

Why learned: nearest-sample routing follows words more than intent ("Who is at the door?" sits
next to "Go to the door"); a classifier weighs the directions that separate the routes. On
queries worded unlike the samples it generalized better; the measurements, the variants that
did not (a calibrated nearest-sample score, descriptions as extra samples, centroids), and the
separate tuning and report sets are in docs/local-models.md.

Hybrid: with a chat model as well, a decision whose margin (best probability minus the second)
is below ``llm_margin`` is handed to the model. LLM mode: each route becomes one tool (its
description and samples in the tool's description) and the model's tool call decides; a reply
that names exactly one route's tool in words counts too (small local models rarely emit tool
calls); otherwise the default route.
"""
from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from typing import Any

import attrs

from emos.config import validators as V

from ..db.spec import DISTANCES
from ..errors import ModelClientError
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


def _description(value: Any) -> str | None:
    if value is None:
        return None
    if not isinstance(value, str) or not value.strip():
        raise ValueError(f"Route.description: expected None or a non-empty string, got {value!r}")
    return value.strip()


@attrs.define
class Route:
    """Where matching queries go (``routes_to``: a Topic, an Action or a name), example queries,
    and optionally a ``description`` in words of what the route is for (given to the model in
    LLM and hybrid mode; vector mode scores by the samples, see the module docstring)."""

    routes_to: Any = attrs.field()
    samples: list[str] = attrs.field(converter=_samples)
    description: str | None = attrs.field(default=None, converter=_description, kw_only=True)

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


def _margin(instance: Any, attribute: Any, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or not 0 <= value <= 1:
        raise ValueError(f"SemanticRouterConfig.{attribute.name}: expected a probability margin in [0, 1], got {value!r}")


SCORINGS = ("learned", "nearest")


@attrs.define(kw_only=True)
class SemanticRouterConfig:
    """``maximum_distance`` is in the units of ``distance_func`` (None: the default for it)."""

    router_name: str = attrs.field(validator=attrs.validators.and_(attrs.validators.instance_of(str),
                                                                   attrs.validators.min_len(1)))
    distance_func: str = attrs.field(default="l2", validator=attrs.validators.in_(DISTANCES))
    maximum_distance: float | None = attrs.field(default=None, validator=V.positive_or_none)
    #: "learned" (a classifier fitted on the samples and descriptions) or "nearest" (nearest sample)
    scoring: str = attrs.field(default="learned", validator=attrs.validators.in_(SCORINGS))
    #: hybrid mode (a chat model as well): decisions with a smaller probability margin go to the model
    llm_margin: float = attrs.field(default=0.2, validator=_margin)

    @property
    def distance_limit(self) -> float:
        """The bound on the nearest sample's distance (both scorings: a query far from every
        sample goes to the default route, as the spec's vector mode says)."""
        return self.effective_maximum_distance

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
    #: vector mode, scoring='learned': probability per route name, and best minus second (None: not scored)
    scores: dict[str, float] = attrs.field(factory=dict)
    margin: float | None = None
    #: "vector", "llm" or "hybrid" (the vector scores were too close; the model decided)
    decided_by: str = "vector"


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


def description_phrases(description: str | None) -> list[str]:
    """A route description cut into its sentences and clauses (each is a training example: a
    whole paragraph embeds to one blurred vector)."""
    return [p.strip() for p in re.split(r"[.;\n]+", description or "") if len(p.strip()) > 2]


class _Classifier:
    """Multinomial logistic regression on unit-length embeddings (scikit-learn, which
    sentence-transformers, and so every vector-mode install, already brings)."""

    C = 1.0  # the regularization; 0.3-30 scored within 1.5 points of each other on the tuning sets

    def __init__(self, vectors: Any, labels: list[str]) -> None:
        try:
            from sklearn.linear_model import LogisticRegression  # type: ignore[import-untyped]
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise ImportError("SemanticRouter scoring='learned' needs scikit-learn (pip install 'emos[agents]'); "
                              "scoring='nearest' does not") from exc
        self.model = LogisticRegression(C=self.C, class_weight="balanced", max_iter=2000)
        self.model.fit(vectors, labels)
        self.classes: list[str] = [str(c) for c in self.model.classes_]

    def probabilities(self, vector: Any) -> dict[str, float]:
        return dict(zip(self.classes, (float(p) for p in self.model.predict_proba(vector)[0])))


class VectorRouter:
    """Vector-mode routing over a ChromaClient (anything with upsert/query, plus ``embed`` for
    ``scoring="learned"``)."""

    def __init__(self, routes: Sequence[Route], db_client: Any, config: SemanticRouterConfig,
                 default_route: Route | None = None) -> None:
        self.routes = _check_routes(routes, default_route)
        self.default_route = default_route or self.routes[0]
        self.config = config
        self.db = db_client
        self._by_name = {r.name: r for r in self.routes}
        self._classifier: _Classifier | None = None
        self._phrases: list[str] = []
        self._phrase_vectors: Any = None  # the description phrases' embeddings (learned scoring)
        if config.scoring == "learned" and len(self.routes) > 1 and not callable(getattr(db_client, "embed", None)):
            raise TypeError(f"SemanticRouter scoring='learned' needs a db_client with embed() (e.g. ChromaClient), "
                            f"got {type(db_client).__name__}; use scoring='nearest'")

    @property
    def learned(self) -> bool:
        return self.config.scoring == "learned" and len(self.routes) > 1

    def initialize(self) -> None:
        """(Re)store every route sample and fit the classifier. Ids are deterministic, so
        restarts do not duplicate."""
        self.db.reset(self.config.router_name)
        documents, metadatas, ids = [], [], []
        for route in self.routes:
            for i, sample in enumerate(route.samples):
                documents.append(sample)
                metadatas.append({"route_name": route.name})
                ids.append(f"{route.name}:{i}")
        self.db.upsert(self.config.router_name, documents, metadatas=metadatas, ids=ids,
                       distance_func=self.config.distance_func)
        self._classifier = None
        self._phrases, self._phrase_vectors = [], None
        if self.learned:
            texts, labels = list(documents), [m["route_name"] for m in metadatas]
            for route in self.routes:
                phrases = description_phrases(route.description)
                texts += phrases
                labels += [route.name] * len(phrases)
            vectors = self.db.embed(texts)
            self._classifier = _Classifier(vectors, labels)
            if len(texts) > len(documents):
                import numpy as np

                self._phrases = texts[len(documents):]
                self._phrase_vectors = np.asarray(vectors, dtype=np.float64)[len(documents):]

    def decide(self, query: str) -> RouteDecision:
        if not isinstance(query, str) or not query.strip():
            raise ValueError("route query: expected a non-empty string")
        if self.learned and self._classifier is None:
            raise RuntimeError(f"router {self.config.router_name!r} is not initialized: call initialize() first")
        vector = self.db.embed([query]) if self._classifier is not None else None
        if vector is not None:
            hits = self.db.query_many(self.config.router_name, [query], n_results=1,
                                      distance_func=self.config.distance_func, embeddings=vector)[0]
        else:
            hits = self.db.query(self.config.router_name, query, n_results=1, distance_func=self.config.distance_func)
        if not hits:
            raise RuntimeError(f"router collection {self.config.router_name!r} is empty: call initialize() first")
        hit = hits[0]
        route_name = hit.metadata.get("route_name")
        if route_name not in self._by_name:
            # A collection written by another router of the same name (a stale store).
            return RouteDecision(self.default_route, hit.distance, hit.document, is_default=True,
                                 reason=f"the nearest sample {hit.document!r} belongs to no route of this router "
                                        f"({route_name!r})")
        scores: dict[str, float] = {}
        margin = None
        best = route_name
        if self._classifier is not None:
            scores = self._classifier.probabilities(vector)
            ranked = sorted(scores, key=scores.__getitem__, reverse=True)
            best, margin = ranked[0], scores[ranked[0]] - scores[ranked[1]]
        limit = self.config.distance_limit
        distance, nearest, what = hit.distance, hit.document, "sample"
        if self._phrase_vectors is not None and vector is not None:
            phrase_distance, phrase = self._nearest_phrase(vector)
            if phrase_distance < distance:
                distance, nearest, what = phrase_distance, phrase, "description phrase"
        if distance > limit:
            return RouteDecision(self.default_route, distance, nearest, is_default=True,
                                 reason=f"no route close enough (nearest {what} {nearest!r} at "
                                        f"{self.config.distance_func} distance {distance:.3f} > {limit:g})",
                                 scores=scores, margin=margin)
        return RouteDecision(self._by_name[best], distance, nearest, scores=scores, margin=margin)

    def _nearest_phrase(self, vector: Any) -> tuple[float, str]:
        """The description phrase nearest to the query's embedding, in ``distance_func``'s units
        as the store measures them (l2: squared; ip: 1 - dot; cosine: 1 - cosine)."""
        import numpy as np

        query = np.asarray(vector, dtype=np.float64).reshape(-1)
        phrases = self._phrase_vectors
        if self.config.distance_func == "l2":
            distances = ((phrases - query) ** 2).sum(axis=1)
        elif self.config.distance_func == "ip":
            distances = 1.0 - phrases @ query
        else:
            norms = np.linalg.norm(phrases, axis=1) * (np.linalg.norm(query) or 1.0)
            distances = 1.0 - (phrases @ query) / np.where(norms == 0, 1.0, norms)
        i = int(np.argmin(distances))
        return float(distances[i]), self._phrases[i]


def _tool_name(route_name: str) -> str:
    # OpenAI tool names allow [a-zA-Z0-9_-] only (max 64); topic names may contain '/'.
    return ("route_to_" + re.sub(r"[^a-zA-Z0-9_-]", "_", route_name))[:64]


def _tool_description(route: Route) -> str:
    about = f"{route.description} " if route.description else ""
    return f"Send the query to {route.name!r}. {about}Use it for queries like: " + "; ".join(route.samples)


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
        self.tools = [ToolSpec(name=tool, description=_tool_description(route), parameters={"type": "object", "properties": {}})
                      for tool, route in self._by_tool.items()]
        # The tools are listed in the prompt as well: small local models (llama.cpp chat
        # templates without tool support) see no tool schema and can only answer in words.
        listing = "\n".join(f"- {t.name}: {t.description}" for t in self.tools)
        self.system_prompt = system_prompt or (
            "You route user queries. Call exactly one of the tools: the one whose examples match "
            f"the intent of the query best. If you cannot call tools, answer with the tool's name only.\n{listing}")
        self._mention = re.compile("|".join(sorted((re.escape(t) for t in self._by_tool), key=len, reverse=True)),
                                   re.IGNORECASE)

    def named_in_text(self, text: str | None) -> Route | None:
        """The one route whose tool name a reply names (None if it names none or several)."""
        found = {m.group(0).lower() for m in self._mention.finditer(text or "")}
        routes = {r.name: r for t, r in self._by_tool.items() if t.lower() in found}
        return next(iter(routes.values())) if len(routes) == 1 else None

    def decide(self, query: str) -> RouteDecision:
        if not isinstance(query, str) or not query.strip():
            raise ValueError("route query: expected a non-empty string")
        request = ChatRequest(messages=[ChatMessage(role="system", content=self.system_prompt),
                                        ChatMessage(role="user", content=query)], tools=self.tools,
                              temperature=0.0, max_tokens=32)
        response = self.chat(request)
        calls = [call.name for call in response.message.tool_calls]
        for name in calls:
            route = self._by_tool.get(name)
            if route is not None:
                return RouteDecision(route, decided_by="llm")
        if not calls:
            route = self.named_in_text(response.message.content)
            if route is not None:
                return RouteDecision(route, decided_by="llm")
        # The names come from the model: shortened, so a rambling answer cannot flood the log.
        reason = (f"the model called no route tool (it called {', '.join(repr(n[:64]) for n in calls[:4])})" if calls
                  else "the model called no route tool")
        return RouteDecision(self.default_route, is_default=True, reason=reason, decided_by="llm")


class HybridRouter:
    """Vector routing first; when its best two route probabilities are closer than
    ``config.llm_margin`` the chat model decides. If the model names no route, the vector
    decision stands (it is still the better-scored guess)."""

    def __init__(self, vector: VectorRouter, llm: LLMRouter) -> None:
        self.vector, self.llm = vector, llm
        self.routes, self.default_route = vector.routes, vector.default_route

    @property
    def config(self) -> SemanticRouterConfig:
        return self.vector.config

    @config.setter
    def config(self, value: SemanticRouterConfig) -> None:
        self.vector.config = value

    def initialize(self) -> None:
        self.vector.initialize()

    def decide(self, query: str) -> RouteDecision:
        decision = self.vector.decide(query)
        if decision.margin is None or decision.margin >= self.vector.config.llm_margin:
            return decision
        try:
            asked = self.llm.decide(query)
        except ModelClientError:  # the model is down: the vector decision stands (the component logs it)
            return decision
        if asked.is_default:
            return decision
        return attrs.evolve(decision, route=asked.route, is_default=False, reason="", decided_by="hybrid")
