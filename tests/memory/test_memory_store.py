"""The spatio-temporal memory index: queries by place, time, label and meaning (by shared words
here; Chroma in test_memory_chroma.py); bounded storage with consolidation into episodes;
impossible ranges refused with the reason."""
from __future__ import annotations

import math

import pytest

from emos.actors.agents.memory import MEMORY_TOOLS, MemoryQueryError, MemoryStore
from emos.actors.agents.types import ToolSpec

pytestmark = pytest.mark.unit


class Clock:
    def __init__(self, t: float = 1000.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def _walk(store: MemoryStore, clock: Clock) -> None:
    """The robot drives through three rooms, seeing things and hearing a sentence."""
    for t, (x, y), labels in ((0, (2.0, 5.5), ["cup", "table"]), (10, (7.5, 2.0), ["sofa", "person"]), (20, (8.0, 6.0), ["plant"])):
        clock.t = 1000.0 + t
        store.update_body(x=x, y=y)
        store.observe_detections(labels)
    clock.t = 1025.0
    store.add("caption", "the user asked for a glass of water")
    store.update_body(battery=0.42, faults={"planner": "algorithm failure: no path"})
    clock.t = 1030.0


def test_spatial_temporal_locate_and_body_status():
    clock = Clock()
    store = MemoryStore(clock=clock)
    _walk(store, clock)
    near_kitchen = store.spatial_query(2.0, 5.0, 1.0)
    assert [r["labels"] for r in near_kitchen] == [["cup", "table"]]
    assert near_kitchen[0]["distance_m"] == 0.5 and near_kitchen[0]["ago_s"] == 30.0
    recent = store.temporal_query(since_s=15)
    assert [r["kind"] for r in recent][:1] == ["detection"] and recent[0]["labels"] == ["plant"]
    assert any("glass of water" in r["text"] for r in recent)
    assert store.temporal_query(since_s=100, until_s=25) == [store.spatial_query(2.0, 5.5, 0.1)[0] | {}] or \
        [r["labels"] for r in store.temporal_query(since_s=100, until_s=25)] == [["cup", "table"]]
    seen = store.locate("person")
    assert seen["found"] and (seen["x"], seen["y"]) == (7.5, 2.0) and seen["ago_s"] == 20.0
    assert store.locate("unicorn") == {"label": "unicorn", "found": False, "text": "never saw a unicorn"}
    body = store.body_status()
    assert body == {"faults": {"planner": "algorithm failure: no path"}, "x": 8.0, "y": 6.0, "battery": "42%"}
    assert "saw" in store.episode_summary(60) and "glass of water" in store.episode_summary(60)


@pytest.mark.parametrize("call, reason", [
    (lambda s: s.spatial_query(1, 1, -2), "radius must be >= 0 m, got -2"),
    (lambda s: s.spatial_query(1, math.nan, 2), "y must be a finite number"),
    (lambda s: s.temporal_query(since_s=-10), "since_s=-10 is in the future"),
    (lambda s: s.temporal_query(since_s=10, until_s=-5), "until_s=-5 is in the future"),
    (lambda s: s.temporal_query(since_s=10, until_s=20), "the window would end before it starts"),
    (lambda s: s.episode_summary(-1), "since_s=-1 is in the future"),
    (lambda s: s.spatial_query(1, 1, 1, n_results=0), "n_results must be an integer in [1, 200]"),
    (lambda s: s.locate(""), "label must be a non-empty text"),
    (lambda s: s.semantic_search("cup", n_results="3"), "n_results must be an integer"),
    (lambda s: s.spatial_query("one", 1, 1), "x must be a number, got str"),
])
def test_impossible_queries_are_refused_with_the_reason(call, reason):
    store = MemoryStore(clock=Clock())
    with pytest.raises(MemoryQueryError, match=reason.replace("[", r"\[").replace("]", r"\]")):
        call(store)


def test_storage_is_bounded_and_old_records_become_model_summarised_episodes():
    clock = Clock(0.0)
    summaries: list[int] = []

    def summarize(records):
        summaries.append(len(records))
        return f"episode of {len(records)}: " + ", ".join(sorted({lbl for r in records for lbl in r.labels}))

    store = MemoryStore(max_records=40, episode_s=10.0, clock=clock, summarize=summarize)
    for i in range(200):
        clock.t = float(i)
        store.update_body(x=i * 0.1, y=0.0)
        store.observe_detections(["cup" if i % 2 else "chair"])
    assert len(store) <= 40 + 1 and store.consolidations > 0 and summaries
    episodes = [r for r in store._records if r.kind == "episode"]
    assert episodes and all(r.text.startswith("episode of") and r.t_end is not None for r in episodes)
    # the gist survives: the oldest times are still covered by an episode, and locate still knows both labels
    assert min(r.t for r in store._records) == 0.0
    assert store.locate("chair")["found"] and store.locate("cup")["ago_s"] == 0.0


def test_a_failing_summariser_keeps_the_gist():
    clock = Clock(0.0)

    def broken(records):
        raise RuntimeError("model down")

    store = MemoryStore(max_records=8, clock=clock, summarize=broken)
    for i in range(12):
        clock.t = float(i)
        store.observe_detections(["cup"])
    ep = next(r for r in store._records if r.kind == "episode")
    assert "saw cup" in ep.text and "summary by the model failed: RuntimeError" in ep.text


def test_tool_specs_are_valid_openai_tools_matching_the_component_methods():
    import inspect

    from emos.actors.agents.components.memory import Memory
    from emos.actors.agents.logic.tools import ToolRegistry

    registry = ToolRegistry()
    for name, spec in MEMORY_TOOLS.items():
        assert isinstance(spec, ToolSpec)
        method = getattr(Memory, name)
        registry.register_tool(method, spec)  # the schema's parameters are the method's arguments
        assert set(spec.parameters["properties"]) <= set(inspect.signature(method).parameters)
    assert sorted(MEMORY_TOOLS) == sorted(["semantic_search", "spatial_query", "temporal_query", "episode_summary",
                                           "locate", "recall", "body_status"])
