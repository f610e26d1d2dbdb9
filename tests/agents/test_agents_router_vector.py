"""Vector-mode SemanticRouter: accuracy on a labeled set with the seed recipe's route samples,
real embeddings and the embedded Chroma store."""
from __future__ import annotations

import json
import os

import pytest

# One xdist worker runs every module that loads the embedding model (torch, sentence-transformers,
# Chroma): it loads them once per run instead of once per worker (tests/conftest.py). The timeout
# bounds a hang only: importing sentence-transformers took over 300 s at load 50 (6 s idle).
pytestmark = [pytest.mark.unit, pytest.mark.statistical, pytest.mark.timeout(900), pytest.mark.xdist_group("embedder")]

os.environ.setdefault("HF_HUB_OFFLINE", "1")

from emos.actors.agents.data import DATA_DIR as DATA  # noqa: E402  (shipped in the package)
from emos.actors.agents.db import ChromaClient, ChromaDB  # noqa: E402 - after HF_HUB_OFFLINE is set: huggingface_hub reads it on import
from emos.actors.agents.logic.router import Route, SemanticRouterConfig, VectorRouter  # noqa: E402 - after HF_HUB_OFFLINE is set: huggingface_hub reads it on import


def load_labeled_set() -> tuple[dict[str, Route], str, list[tuple[str, str]]]:
    spec = json.loads((DATA / "router_routes.json").read_text())
    routes = {name: Route(routes_to=name, samples=samples) for name, samples in spec["routes"].items()}
    rows = [line.rstrip("\n").split("\t") for line in (DATA / "router_labeled.tsv").read_text().splitlines()
            if line.strip() and not line.startswith("#")]
    return routes, spec["default_route"], [(q, e) for q, e in rows]


@pytest.fixture(scope="module")
def labeled():
    return load_labeled_set()


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    return ChromaClient(ChromaDB(path=str(tmp_path_factory.mktemp("router"))))


def test_labeled_set_is_big_enough_and_balanced(labeled):
    routes, default, rows = labeled
    assert len(rows) >= 60 and len(routes) == 3
    assert {expected for _, expected in rows} == set(routes)
    assert min(sum(e == r for _, e in rows) for r in routes) >= 20


def test_vector_router_accuracy_on_the_labeled_set(labeled, client, capsys):
    routes, default, rows = labeled
    router = VectorRouter(list(routes.values()), client, SemanticRouterConfig(router_name="go-to-router"),
                          default_route=routes[default])
    router.initialize()
    correct = sum(router.decide(query).route.name == expected for query, expected in rows)
    accuracy = correct / len(rows)
    with capsys.disabled():
        print(f"\nvector router accuracy: {correct}/{len(rows)} = {accuracy:.3f}")
    # Measured 0.96 (72/75) with all-MiniLM-L6-v2; the floor leaves room for numeric noise only.
    assert accuracy >= 0.9


def test_samples_route_to_themselves_and_far_queries_take_the_default(labeled, client):
    routes, default, _ = labeled
    router = VectorRouter(list(routes.values()), client,
                          SemanticRouterConfig(router_name="strict-router", maximum_distance=0.3),
                          default_route=routes["goto_in"])
    router.initialize()
    for route in routes.values():
        for sample in route.samples:
            decision = router.decide(sample)
            assert decision.route is route and decision.distance < 1e-3 and not decision.is_default
    decision = router.decide("The mitochondria is the powerhouse of the cell")
    assert decision.is_default and decision.route is routes["goto_in"] and decision.distance > 0.3


def test_initialize_is_idempotent(labeled, client):
    routes, default, _ = labeled
    router = VectorRouter(list(routes.values()), client, SemanticRouterConfig(router_name="again-router"))
    router.initialize()
    router.initialize()
    assert client.count("again-router") == sum(len(r.samples) for r in routes.values())


def test_router_configuration_errors(labeled, client):
    routes, _, _ = labeled
    with pytest.raises(ValueError, match="default_route"):
        VectorRouter([routes["goto_in"]], client, SemanticRouterConfig(router_name="r-1"),
                     default_route=routes["llm_in"])
    with pytest.raises(ValueError, match="maximum_distance"):
        SemanticRouterConfig(router_name="r-1", maximum_distance=-1)
    with pytest.raises(TypeError, match="one str"):
        Route(routes_to="x", samples="go to the door")
    with pytest.raises(ValueError, match="same target"):
        VectorRouter([routes["goto_in"], routes["goto_in"]], client, SemanticRouterConfig(router_name="r-1"))
    assert SemanticRouterConfig(router_name="r", distance_func="cosine").effective_maximum_distance == 0.75
