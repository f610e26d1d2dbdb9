"""Issue 40 item 4: vector routing that generalizes to wording it was not given.

Scored on report_queries.tsv, a set written after the router change was frozen and never used to
choose anything (the tuning sets are tuning_queries.tsv, tuning_queries_2.tsv and the package's
router_labeled.tsv). The complete-agent recipe's route samples, real all-MiniLM-L6-v2 embeddings,
the embedded Chroma store. The old rule (scoring="nearest") is scored on the same queries so the
report shows both; the floors sit a few points under the measured figures (docs/local-models.md)."""
from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

# The timeout bounds a hang only: loading the embedding model took 155 s on the 2-core machine at
# load 22 (6 s idle), and the test routes 216 queries. One xdist worker runs every module that
# loads the embedding model (torch, sentence-transformers, Chroma): it loads them once per run
# instead of once per worker (tests/conftest.py).
pytestmark = [pytest.mark.unit, pytest.mark.statistical, pytest.mark.timeout(900), pytest.mark.xdist_group("embedder")]

os.environ.setdefault("HF_HUB_OFFLINE", "1")

from emos.actors.agents.data import DATA_DIR  # noqa: E402
from emos.actors.agents.db import ChromaClient, ChromaDB  # noqa: E402 - after HF_HUB_OFFLINE is set
from emos.actors.agents.logic.router import (  # noqa: E402
    HybridRouter,
    LLMRouter,
    Route,
    SemanticRouterConfig,
    VectorRouter,
    description_phrases,
)
from emos.actors.agents.types import ChatMessage, ChatResponse  # noqa: E402

HERE = Path(__file__).parent


def _rows(path: Path) -> list[tuple[str, str]]:
    rows = []
    for number, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip() or line.startswith("#"):
            continue
        query, _, route = line.partition("\t")
        assert query and route, f"{path.name}:{number}: expected 'query<TAB>route'"
        rows.append((query, route))
    return rows


SPEC = json.loads((HERE / "routes.json").read_text())
REPORT = _rows(HERE / "report_queries.tsv")
REPORT_2 = _rows(HERE / "report_queries_2.tsv")  # a second unseen set, written a session later
REPORT_3 = _rows(HERE / "report_queries_3.tsv")  # a third, written before the new bound was scored
TUNING = {name: _rows(path) for name, path in (("tuning_queries.tsv", HERE / "tuning_queries.tsv"),
                                                ("tuning_queries_2.tsv", HERE / "tuning_queries_2.tsv"),
                                                ("router_labeled.tsv", DATA_DIR / "router_labeled.tsv"))}


def _routes(descriptions: bool) -> dict[str, Route]:
    return {name: Route(routes_to=name, samples=samples,
                        description=SPEC["descriptions"][name] if descriptions else None)
            for name, samples in SPEC["routes"].items()}


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    db = ChromaClient(ChromaDB(path=str(tmp_path_factory.mktemp("router-generalize"))))
    db.initialize()
    yield db
    db.deinitialize()


def _accuracy(client, name: str, scoring: str, descriptions: bool, rows, maximum_distance: float | None = None,
              samples_bound: bool = False) -> float:
    routes = _routes(descriptions)
    config = SemanticRouterConfig(router_name=name, scoring=scoring, maximum_distance=maximum_distance)
    router = VectorRouter(list(routes.values()), client, config,
                          default_route=routes[SPEC["default_route"]])
    router.initialize()
    if samples_bound:
        router._phrase_vectors = None  # the session-21 default: the distance bound on the samples only
    return sum(router.decide(query).route.name == expected for query, expected in rows) / len(rows)


def test_the_report_set_is_separate_from_every_tuning_set_and_balanced():
    assert SPEC["routes"] == json.loads((DATA_DIR / "router_routes.json").read_text())["routes"]  # the recipe's samples
    seen = {q.lower() for rows in TUNING.values() for q, _ in rows}
    samples = {s.lower() for samples in SPEC["routes"].values() for s in samples}
    for report in (REPORT, REPORT_2, REPORT_3):
        assert not seen & {q.lower() for q, _ in report}
        assert not samples & {q.lower() for q, _ in report}
        assert len(report) >= 60 and {r for _, r in report} == set(SPEC["routes"])
        assert min(sum(r == name for _, r in report) for name in SPEC["routes"]) >= 20
    assert not {q.lower() for q, _ in REPORT} & {q.lower() for q, _ in REPORT_2}
    assert not {q.lower() for q, _ in REPORT + REPORT_2} & {q.lower() for q, _ in REPORT_3}


def test_learned_routing_generalizes_to_the_report_set(client, capsys):
    before = _accuracy(client, "report-nearest", "nearest", False, REPORT)
    learned = _accuracy(client, "report-learned", "learned", False, REPORT)
    described = _accuracy(client, "report-described", "learned", True, REPORT)
    with capsys.disabled():
        print(f"\nreport set ({len(REPORT)} queries, default distance bound): nearest sample {before:.3f}, learned {learned:.3f}, "
              f"learned + descriptions {described:.3f}")
    assert described >= 0.88  # measured 0.889 (64/72), 0.903 since the bound counts description phrases
    assert learned > before
    second = _accuracy(client, "report2-described", "learned", True, REPORT_2)
    unbounded = [_accuracy(client, f"report{i}-unbounded", "learned", True, rows, maximum_distance=4.0)
                 for i, rows in ((1, REPORT), (2, REPORT_2))]
    with capsys.disabled():
        print(f"second report set ({len(REPORT_2)} queries): learned + descriptions {second:.3f}; "
              f"without the distance bound (maximum_distance=4.0): {unbounded[0]:.3f} and {unbounded[1]:.3f}")
    assert second >= 0.87  # measured 0.889 (64/72) when first scored: a regression guard
    assert min(unbounded) >= 0.89  # measured 0.903 and 0.917 (docs/local-models.md)


def test_descriptions_become_training_phrases_and_hybrid_asks_the_model_only_on_close_calls(client):
    assert description_phrases("Go somewhere. Fetch, bring; carry things\nor come here.") == [
        "Go somewhere", "Fetch, bring", "carry things", "or come here"]
    routes = _routes(True)
    asked: list[str] = []

    def model(request):  # a model that always says "vision": shows when it was asked
        asked.append(request.messages[-1].content)
        return ChatResponse(message=ChatMessage(role="assistant", content="route_to_mllm_in"))

    vector = VectorRouter(list(routes.values()), client, SemanticRouterConfig(router_name="hybrid-r", llm_margin=0.2),
                          default_route=routes["llm_in"])
    hybrid = HybridRouter(vector, LLMRouter(list(routes.values()), model, default_route=routes["llm_in"]))
    hybrid.initialize()
    clear = hybrid.decide("Go to the kitchen")
    assert clear.route.name == "goto_in" and clear.decided_by == "vector" and clear.margin >= 0.2 and not asked
    close = next(q for q, _ in TUNING["tuning_queries_2.tsv"] if vector.decide(q).margin < 0.2)
    decision = hybrid.decide(close)
    assert asked == [close] and decision.route.name == "mllm_in" and decision.decided_by == "hybrid"


def test_nearest_scoring_keeps_the_original_rule_and_learned_needs_an_embedder(client):
    routes = _routes(False)
    with pytest.raises(TypeError, match="scoring='learned' needs a db_client with embed"):
        VectorRouter(list(routes.values()), object(), SemanticRouterConfig(router_name="no-embed"))
    with pytest.raises(ValueError, match="scoring"):
        SemanticRouterConfig(router_name="x", scoring="magic")
    with pytest.raises(ValueError, match="Route.description"):
        Route(routes_to="x", samples=["a"], description="  ")
    router = VectorRouter(list(routes.values()), client, SemanticRouterConfig(router_name="far", scoring="learned",
                                                                            maximum_distance=0.3),
                          default_route=routes["llm_in"])
    router.initialize()
    far = router.decide("The mitochondria is the powerhouse of the cell")
    assert far.is_default and far.reason.startswith("no route close enough")


FAR = ["zxqv 1234 lorem ipsum", "asdf qwer zxcv", "lorem ipsum dolor sit amet", "blorp fnord quux", "%%%% #### @@@@",
       "1234567890", "The mitochondria is the powerhouse of the cell"]


def test_the_default_bound_counts_description_phrases_and_keeps_far_queries_on_the_default_route(client, capsys):
    """The default's distance bound measures from the route samples and the phrases of
    the route descriptions (cosine 0.25 from anything a route declares). Chosen on the tuning sets
    (0.932 -> 0.937 over their 207 queries, far queries unchanged), then scored once on
    report_queries_3.tsv: 0.931 (67/72); the old default 0.917, unbounded 0.931 (docs/local-models.md)."""
    new = _accuracy(client, "report3-new", "learned", True, REPORT_3)
    old = _accuracy(client, "report3-old", "learned", True, REPORT_3, samples_bound=True)
    with capsys.disabled():
        print(f"\nthird report set ({len(REPORT_3)} queries): default {new:.3f}; bound on the samples only (before) {old:.3f}")
    assert new >= 0.91 and new >= old  # measured 0.931 and 0.917: regression guards
    routes = _routes(True)
    router = VectorRouter(list(routes.values()), client, SemanticRouterConfig(router_name="far3"),
                          default_route=routes[SPEC["default_route"]])
    router.initialize()
    far = [router.decide(q) for q in FAR]
    assert all(d.is_default and d.reason.startswith("no route close enough") for d in far), [(d.distance, d.reason) for d in far]
    near = router.decide("Describe the scene around the robot")  # a description phrase itself
    assert near.route.name == "mllm_in" and near.distance < 1e-6 and near.matched_sample == "Describe the scene around the robot"
