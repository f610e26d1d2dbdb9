"""The unseen-set measurement (docs/local-models.md): the router's default (the distance bound counts
the route descriptions' phrases) against the previous default (the bound on the samples only) and
the unbounded router, on the tuning sets, then on an unseen set.

    python3 tests/router_generalize/score_unseen_sets.py             # tuning sets only
    python3 tests/router_generalize/score_unseen_sets.py --report3   # + the third unseen set (scored once)
    python3 tests/router_generalize/score_unseen_sets.py --report12  # the first two unseen sets instead
"""
from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("HF_HUB_OFFLINE", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from emos.actors.agents.data import DATA_DIR
from emos.actors.agents.db import ChromaClient, ChromaDB
from emos.actors.agents.logic.router import Route, SemanticRouterConfig, VectorRouter

HERE = Path(__file__).resolve().parent
FAR = ["zxqv 1234 lorem ipsum", "asdf qwer zxcv", "lorem ipsum dolor sit amet", "blorp fnord quux", "%%%% #### @@@@",
       "1234567890", "The mitochondria is the powerhouse of the cell", "qwertyuiop"]


def rows(path: Path) -> list[tuple[str, str]]:
    out = []
    for line in path.read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            query, _, route = line.partition("\t")
            out.append((query, route))
    return out


def main() -> None:
    spec = json.loads((HERE / "routes.json").read_text())
    routes = {n: Route(routes_to=n, samples=s, description=spec["descriptions"][n]) for n, s in spec["routes"].items()}
    db = ChromaClient(ChromaDB(path=tempfile.mkdtemp()))
    db.initialize()

    def router(name: str, maximum_distance: float | None = None, samples_bound: bool = False) -> VectorRouter:
        r = VectorRouter(list(routes.values()), db, SemanticRouterConfig(router_name=name, maximum_distance=maximum_distance),
                         default_route=routes[spec["default_route"]])
        r.initialize()
        if samples_bound:
            r._phrase_vectors = None  # the previous default: the bound on the samples only
        return r

    variants = {"previous default (bound on samples)": router("old", samples_bound=True),
                "default (samples + description phrases)": router("new"),
                "unbounded (maximum_distance=4.0)": router("unbounded", 4.0)}
    sets = [(name, rows(path)) for name, path in (("tuning_queries.tsv", HERE / "tuning_queries.tsv"),
                                                  ("tuning_queries_2.tsv", HERE / "tuning_queries_2.tsv"),
                                                  ("router_labeled.tsv", DATA_DIR / "router_labeled.tsv"))]
    if "--report12" in sys.argv:
        sets = [("report_queries.tsv", rows(HERE / "report_queries.tsv")), ("report_queries_2.tsv", rows(HERE / "report_queries_2.tsv"))]
    if "--report3" in sys.argv:
        sets.append(("report_queries_3.tsv", rows(HERE / "report_queries_3.tsv")))
    try:
        for name, r in variants.items():
            print(name)
            for set_name, queries in sets:
                got = [r.decide(q).route.name for q, _ in queries]
                ok = sum(g == e for g, (_, e) in zip(got, queries))
                print(f"   {set_name:24s} {ok}/{len(queries)} = {ok / len(queries):.3f}")
                if set_name.startswith("report"):
                    for g, (q, e) in zip(got, queries):
                        if g != e:
                            print(f"      miss: {q!r} expected {e} got {g}")
            print(f"   far queries to the default route: {sum(r.decide(q).is_default for q in FAR)}/{len(FAR)}")
    finally:
        db.deinitialize()


if __name__ == "__main__":
    main()
