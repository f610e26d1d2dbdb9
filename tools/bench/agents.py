"""``emos bench agents``: semantic-routing decision time and accuracy, and vector-store query
time with 10,000 stored map entries, all on CPU with the packaged embedding model.

Route time is one full vector-mode decision (embed the query + nearest sample in the embedded
Chroma store). The map query time is the store's nearest-neighbour search alone (the query is
embedded beforehand), so it measures Chroma with 10,000 entries, not the embedding model; the
table also shows the end-to-end figure.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np


def _agents_data() -> Path:
    """The router samples shipped with the agents package (wheel too). find_spec locates the
    package without importing it, so `--help` stays cheap."""
    spec = importlib.util.find_spec("emos.actors.agents")
    if spec is None or spec.origin is None:
        raise SystemExit("emos bench agents: the package emos.actors.agents is not installed")
    return Path(spec.origin).resolve().parent / "data"


DEFAULT_DATA = _agents_data()

_OBJECTS = ["chair", "table", "sofa", "door", "window", "fridge", "sink", "bed", "lamp", "plant", "cup",
            "bottle", "laptop", "television", "bookshelf", "person", "dog", "cat", "box", "trash bin"]
_COLOURS = ["red", "blue", "green", "yellow", "white", "black", "wooden", "metal", "small", "large"]
_ROOMS = ["kitchen", "office", "bedroom", "hallway", "living room", "bathroom", "garage", "lobby"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print the result as JSON only")
    parser.add_argument("--data", default=str(DEFAULT_DATA),
                        help="folder with router_routes.json and router_labeled.tsv (default: the data shipped in emos.actors.agents.data)")
    parser.add_argument("--entries", type=int, default=10_000, help="map entries stored for the query benchmark")
    parser.add_argument("--repeats", type=int, default=3, help="passes over the labeled queries for route timing")
    parser.add_argument("--queries", type=int, default=200, help="map queries timed")
    parser.add_argument("--threads", type=int, default=1,
                        help="torch intra-op threads for the embedding model (default 1, see SentenceEmbedder)")
    parser.add_argument("--llm-queries", type=int, default=40, help="questions timed through the LLM component")
    parser.add_argument("--vision-seconds", type=float, default=10.0, help="seconds of 30 Hz frames into Vision")
    parser.add_argument("--swaps", type=int, default=5, help="primary-server kills timed for the hot swap")


def _load_labeled(folder: Path):
    from emos.actors.agents.logic.router import Route

    routes_file, labeled_file = folder / "router_routes.json", folder / "router_labeled.tsv"
    for path in (routes_file, labeled_file):
        if not path.is_file():
            raise FileNotFoundError(f"router benchmark data {str(path)!r} not found (use --data FOLDER)")
    spec = json.loads(routes_file.read_text())
    routes = {name: Route(routes_to=name, samples=samples) for name, samples in spec["routes"].items()}
    rows = []
    for number, line in enumerate(labeled_file.read_text().splitlines(), 1):
        if not line.strip() or line.startswith("#"):
            continue
        parts = line.split("\t")
        if len(parts) != 2 or parts[1] not in routes:
            raise ValueError(f"{labeled_file}:{number}: expected 'query<TAB>route' with a known route, got {line!r}")
        rows.append((parts[0], parts[1]))
    return routes, routes[spec["default_route"]], rows


def _percentile(samples: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(samples) * 1000.0, q))


def bench_router(client, folder: Path, repeats: int) -> dict:
    """Decision time, accuracy at the default ``maximum_distance``, and a tuned threshold:
    chosen on the even-numbered labeled queries, reported (accuracy and confusion matrix) on
    the odd-numbered ones, which it never saw."""
    from emos.actors.agents.logic.router import DEFAULT_MAXIMUM_DISTANCE, SemanticRouterConfig, VectorRouter

    routes, default, rows = _load_labeled(folder)
    router = VectorRouter(list(routes.values()), client, SemanticRouterConfig(router_name="bench-router"),
                          default_route=default)
    router.initialize()
    for query, _ in rows[:5]:  # warm-up: first calls pay for lazy initialisation
        router.decide(query)
    times, correct, nearest = [], 0, []
    for rep in range(max(1, repeats)):
        for query, expected in rows:
            start = time.perf_counter()
            decision = router.decide(query)
            times.append(time.perf_counter() - start)
            if rep == 0:
                correct += decision.route.name == expected
                hit = client.query("bench-router", query, n_results=1)[0]
                nearest.append((hit.metadata["route_name"], hit.distance, expected))
    names = sorted(routes)
    tune, test = nearest[0::2], nearest[1::2]

    def predict(item, threshold):
        route, distance, _ = item
        return route if distance <= threshold else default.name

    candidates = np.round(np.arange(0.3, 2.0001, 0.05), 2)
    scores = [sum(predict(i, t) == i[2] for i in tune) for t in candidates]
    best = float(candidates[int(np.argmax(scores))])
    confusion = {e: {p: 0 for p in names} for e in names}
    for item in test:
        confusion[item[2]][predict(item, best)] += 1
    test_correct = sum(confusion[n][n] for n in names)
    return {"p50": _percentile(times, 50), "p95": _percentile(times, 95), "n": len(times),
            "accuracy": correct / len(rows), "correct": correct, "labeled": len(rows),
            "default_threshold": DEFAULT_MAXIMUM_DISTANCE["l2"], "tuned_threshold": best,
            "tune_accuracy": max(scores) / len(tune), "test_accuracy": test_correct / len(test),
            "test_size": len(test), "confusion": confusion}


def bench_map_query(client, entries: int, queries: int, seed: int = 0) -> dict:
    from emos.actors.agents.logic.map_encoding import MapConfig, MapEncoder, MapLayer

    rng = np.random.default_rng(seed)
    vocabulary = [f"{c} {o} in the {r}" for o in _OBJECTS for c in _COLOURS[:5] for r in _ROOMS[:2]]
    vectors = client.embed(vocabulary)
    pick = rng.integers(0, len(vocabulary), entries)
    positions = rng.uniform(-50.0, 50.0, (entries, 2))
    encoder = MapEncoder([MapLayer(subscribes_to="detections", temporal_change=True)], client,
                         MapConfig(map_name="bench-map"), resolution=0.05)
    client.reset("bench-map")
    start = time.perf_counter()
    encoder.encode_many("detections", [vocabulary[i] for i in pick], positions,
                        timestamps=np.arange(entries, dtype=float).tolist(), embeddings=vectors[pick])
    insert_s = time.perf_counter() - start
    stored = client.count("bench-map")
    texts = [f"where is the {o}?" for o in _OBJECTS]
    query_vectors = client.embed(texts)
    for i in range(5):
        client.query_many("bench-map", [texts[i]], n_results=1, embeddings=query_vectors[i:i + 1])
    search, end_to_end = [], []
    for i in range(queries):
        j = i % len(texts)
        start = time.perf_counter()
        client.query_many("bench-map", [texts[j]], n_results=1, embeddings=query_vectors[j:j + 1])
        search.append(time.perf_counter() - start)
    for i in range(min(queries, 50)):
        start = time.perf_counter()
        client.query("bench-map", texts[i % len(texts)], n_results=1)
        end_to_end.append(time.perf_counter() - start)
    return {"p50": _percentile(search, 50), "p95": _percentile(search, 95), "stored": stored,
            "insert_s": insert_s, "end_to_end_p50": _percentile(end_to_end, 50)}


def run(args: argparse.Namespace) -> int:
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    from emos.actors.agents.db import ChromaClient, ChromaDB

    if args.entries < 1 or args.queries < 1 or args.threads < 1:
        raise SystemExit("--entries, --queries and --threads must be positive")
    with tempfile.TemporaryDirectory(prefix="emos-bench-agents-") as folder:
        client = ChromaClient(ChromaDB(path=folder))
        client.initialize()
        client.embed(["warm up"])  # load the model, then apply --threads over its default
        import torch

        torch.set_num_threads(args.threads)
        route = bench_router(client, Path(args.data), args.repeats)
        query = bench_map_query(client, args.entries, args.queries)
        client.deinitialize()
    from .agents_system import bench_hotswap, bench_llm_overhead, bench_vision

    if args.llm_queries < 1 or args.vision_seconds <= 0 or args.swaps < 1:
        raise SystemExit("--llm-queries, --vision-seconds and --swaps must be positive")
    llm = bench_llm_overhead(args.llm_queries)
    vision = bench_vision(args.vision_seconds)
    swap = bench_hotswap(args.swaps)
    if args.json:
        print(json.dumps({"route_ms": {"p50": round(route["p50"], 3), "p95": round(route["p95"], 3)},
                          "route_accuracy": round(route["accuracy"], 4),
                          "chroma_query_ms": {"p50": round(query["p50"], 3)},
                          "router_split": {"tuned_maximum_distance": route["tuned_threshold"],
                                           "test_accuracy": round(route["test_accuracy"], 4),
                                           "confusion": route["confusion"]},
                          "llm_overhead_ms": llm["overhead"],
                          "vision": {"fps": vision["fps"], "p95_ms": vision["p95_ms"], "dropped": vision["dropped"]},
                          "hotswap_ms": {"p50": swap["p50"], "p95": swap["p95"]}}))
        return 0
    rows = [
        ("route decision (embed + nearest), p50", f"{route['p50']:.2f} ms", "target <= 30 ms"),
        ("route decision (embed + nearest), p95", f"{route['p95']:.2f} ms", f"{route['n']} decisions"),
        ("router accuracy (default threshold)", f"{route['accuracy']:.1%}",
         f"{route['correct']}/{route['labeled']} labeled queries, l2 <= {route['default_threshold']}"),
        ("router accuracy, held-out half", f"{route['test_accuracy']:.1%}",
         f"l2 <= {route['tuned_threshold']} tuned on the other half ({route['tune_accuracy']:.1%} there); target >= 90%"),
        ("map query, 1 nearest, p50", f"{query['p50']:.2f} ms", f"{query['stored']} entries; target <= 20 ms"),
        ("map query, 1 nearest, p95", f"{query['p95']:.2f} ms", ""),
        ("map query incl. embedding, p50", f"{query['end_to_end_p50']:.2f} ms", ""),
        ("map insert (pre-embedded)", f"{query['insert_s']:.1f} s", f"{query['stored']} entries"),
        ("LLM component overhead, p50", f"{llm['overhead']['p50']:.2f} ms",
         f"topic->component->topic {llm['component']['p50']:.2f} ms vs direct {llm['direct']['p50']:.2f} ms; target <= 5 ms"),
        ("LLM component overhead, p95", f"{llm['overhead']['p95']:.2f} ms", f"{llm['n']} questions"),
        ("Vision, on-board detector", f"{vision['fps']:.1f} fps",
         f"640x480 at 30 Hz: {vision['answered']}/{vision['sent']} frames answered, {vision['dropped']} dropped (latest-frame)"),
        ("Vision frame-to-detections, p95", f"{vision['p95_ms']:.0f} ms", ""),
        ("hot swap to the backup, p50", f"{swap['p50']:.0f} ms", "primary SIGKILLed -> first answer from the backup"),
        ("hot swap to the backup, p95", f"{swap['p95']:.0f} ms", f"{swap['n']} kills; target <= 2000 ms"),
    ]
    width = max(len(r[0]) for r in rows)
    print(f"{'measure':<{width}}  {'value':>10}  note")
    for name, value, note in rows:
        print(f"{name:<{width}}  {value:>10}  {note}")
    print("\nrouter confusion matrix on the held-out half (rows: expected, columns: routed to)")
    names = sorted(route["confusion"])
    print(" " * 10 + "".join(f"{n:>10}" for n in names))
    for expected in names:
        print(f"{expected:>10}" + "".join(f"{route['confusion'][expected][p]:>10}" for p in names))
    return 0
