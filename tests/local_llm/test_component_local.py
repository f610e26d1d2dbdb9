"""Issue 40 item 1: the LLM and VLM components run the real SmolLM2 inside their own process
(`enable_local_model=True`, no model server anywhere), and a recipe's fallback ladder moves an
LLM from a model server that is killed mid-run to the local model, which then answers.

Each recipe runs under `emos run` in its own process tree (multi_processing=True)."""
from __future__ import annotations

import time

import numpy as np
import pytest

from emos.msgs import Detections, Image, String
from emos.msgs.status import ComponentStatus
from emos.tools.bench.agents_system import ModelServer, RunningRecipe, _server_on, _wait_one
from emos.tools.bench.local_llm import _answer_after, _wait_for, _wait_standby, swap_recipe

# Bounds a hang only: the processes load a 98 MB model on a machine that may be busy.
pytestmark = [pytest.mark.process, pytest.mark.timeout(900)]

LOCAL_RECIPE = """
from emos import Launcher, Topic
from emos.actors.agents import LLM, LLMConfig, VLM, VLMConfig
q = Topic(name="lq", msg_type="String")
a = Topic(name="la", msg_type="String")
img = Topic(name="limg", msg_type="Image")
va = Topic(name="lva", msg_type="String")
ga = Topic(name="lga", msg_type="Detections")
llm = LLM(inputs=[q], outputs=[a], trigger=q, component_name="local_talker", enable_local_model=True,
          config=LLMConfig(max_new_tokens=24, temperature=0.0, ncpu_local_model=2, stream=True))
vlm = VLM(inputs=[q, img], outputs=[va], trigger=q, component_name="local_eyes", enable_local_model=True,
          config=VLMConfig(max_new_tokens=24, temperature=0.0, ncpu_local_model=1))
grounder = VLM(inputs=[q, img], outputs=[ga], trigger=q, component_name="local_grounder", enable_local_model=True,
               config=VLMConfig(task="grounding", ncpu_local_model=1))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[llm, vlm, grounder])
launcher.bringup()
"""


def _collect(sub, seconds: float) -> list:
    got, end = [], time.monotonic() + seconds
    while time.monotonic() < end:
        got += sub.take()
        time.sleep(0.01)
    return got


def test_llm_and_vlm_answer_with_the_local_model_in_their_own_process():
    recipe = RunningRecipe(LOCAL_RECIPE, ["local_talker", "local_eyes", "local_grounder"], timeout=180)
    try:
        pub = recipe.publisher("/lq", String)
        img = recipe.publisher("/limg", Image)
        answers, seen = recipe.subscriber("/la", String), recipe.subscriber("/lva", String)
        boxes = recipe.subscriber("/lga", Detections)
        status = recipe.subscriber("/local_grounder/status", ComponentStatus)
        img.publish(Image.from_numpy(np.zeros((32, 32, 3), dtype=np.uint8)))
        time.sleep(0.5)
        pub.publish(String(data="What is a kitchen used for?"))
        first, _ = _wait_one(answers, timeout=120)
        assert first.data.strip()  # streamed: the first sentence (or the whole short answer)
        looked, _ = _wait_one(seen, timeout=120)
        assert looked.data.strip()  # answered from the text; the image was described as unseen
        # The grounding VLM refuses (a text-only model cannot ground), says why, publishes no boxes.
        end = time.monotonic() + 60
        refusal = None
        while refusal is None and time.monotonic() < end:
            refusal = next((m.message for m in status.take() if "is text-only" in m.message), None)
            time.sleep(0.05)
        assert refusal is not None and "'grounding' task" in refusal
        assert _collect(boxes, 1.0) == []
    finally:
        recipe.stop()


def test_a_killed_model_server_is_replaced_by_the_local_model_through_the_ladder_and_comes_back():
    server = ModelServer()
    recipe = None
    try:
        recipe = RunningRecipe(swap_recipe(server.port, standby=False, threads=1), ["local_llm"], timeout=180)
        pub, sub = recipe.publisher("/local_q", String), recipe.subscriber("/local_a", String)
        # The ladder holds fallback_to_local: the model is loaded and warmed at activation, in the
        # background, before any failure (the swap does not wait for the GGUF to load).
        state = _wait_standby(recipe)
        assert state["role"] == "standby" and not state["active"] and state["error"] is None
        for round_ in range(2):  # the second kill proves the way back to the server is whole
            pub.publish(String(data=f"hello server {round_}"))
            _wait_for(sub, f"You said: hello server {round_}", 60)  # the scripted model server answers
            server.kill()  # mid-run: SIGKILL, nothing graceful
            text, _, _ = _answer_after(sub, pub, time.perf_counter(), ask_every=0.5, timeout=120)
            assert text.strip() and not text.startswith("You said:")  # SmolLM2's own words
            assert recipe.call_method("local_llm", "local_model_state")["active"]
            pub.publish(String(data="And what is a bedroom?"))
            later = [m.data for m in _collect(sub, 5.0)]
            assert not any(t.startswith("You said:") for t in later)  # it stays on the local model
            # The server comes back (a new process on the same port): the component returns to it.
            server = _server_on(server.port)
            assert recipe.call_method("local_llm", "change_model_client", "primary") is True
            sub.take()
        pub.publish(String(data="hello again"))
        _wait_for(sub, "You said: hello again", 60)
        assert not recipe.call_method("local_llm", "local_model_state")["active"]
    finally:
        if recipe is not None:
            recipe.stop()
        server.kill()
