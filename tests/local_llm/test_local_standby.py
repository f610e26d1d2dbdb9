"""Issue 40, the fast swap: a local model standing by for `fallback_to_local()` is loaded and
warmed at activation in a thread of its own (the real SmolLM2 through llama.cpp), and a load
that fails is reported with the file named, not swallowed."""
from __future__ import annotations

import struct

import pytest

from emos.actors.agents.clients import OllamaClient
from emos.actors.agents.components.llm import LLM, LLMConfig
from emos.actors.agents.models import OllamaModel
from emos.actors.agents.server.local_client import LocalLLM, LocalLLMClient
from emos.actors.agents.server.local_standby import LocalStandby
from emos.events.action import Action
from emos.io.topic import Topic

# Not pure (the real model is loaded), but no process is started.
pytestmark = [pytest.mark.process, pytest.mark.timeout(600)]

Q = Topic(name="q", msg_type="String")
A = Topic(name="a", msg_type="String")


class _Log:
    def __init__(self) -> None:
        self.errors: list[str] = []

    def error(self, msg: str, *args: object) -> None:
        self.errors.append(msg % args)

    def warning(self, msg: str, *args: object) -> None:
        pass

    info = warning


def _laddered(name: str, config: LLMConfig) -> LLM:
    llm = LLM(inputs=[Q], outputs=[A], trigger=Q, component_name=name, config=config,
              model_client=OllamaClient(OllamaModel(name="m", checkpoint="x"), port=9))
    llm.on_component_fail(action=[Action(llm.reconnect_model_client), Action(llm.fallback_to_local)])
    return llm


def test_the_standby_model_is_loaded_and_warmed_in_its_own_thread():
    client = LocalLLMClient(LocalLLM(n_threads=1, n_ctx=512))
    log = _Log()
    standby = LocalStandby(client, "talker", log, system_prompt="You are a robot in a house.")
    standby.start()
    try:
        assert standby.wait(300), "the standby load did not end"
        assert standby.ready and client.loaded and log.errors == []
        assert standby.load_s is not None and standby.warm_s is not None  # one throw-away answer was generated
    finally:
        standby.stop()
        client.deinitialize()


def test_a_ladder_with_fallback_to_local_preloads_the_model_and_a_failed_load_is_reported(tmp_path):
    # A header llama.cpp's loader accepts as GGUF, tensors it cannot load: only the load fails.
    bad = tmp_path / "broken.gguf"
    bad.write_bytes(b"GGUF" + struct.pack("<IQQ", 3, 10, 5) + b"\0" * 64)
    llm = _laddered("talker", LLMConfig(local_model_path=str(bad), ncpu_local_model=1))
    assert llm.local_model_state()["role"] == "none"  # nothing is created in the recipe line
    llm.activate_resources()  # what activation runs in the worker: it returns without waiting for the load
    try:
        assert llm._standby is not None and llm._standby.wait(300)
        state = llm.local_model_state()
        assert state["role"] == "standby" and not state["active"] and not state["loaded"]
        assert "broken.gguf" in state["error"]  # kept, and named: fallback_to_local reports it again
    finally:
        llm.release_resources()


def test_without_fallback_to_local_nothing_is_loaded_ahead():
    llm = LLM(inputs=[Q], outputs=[A], trigger=Q, component_name="plain",
              model_client=OllamaClient(OllamaModel(name="m", checkpoint="x"), port=9))
    llm.activate_resources()
    try:
        assert llm._standby is None and llm.local_model_state()["role"] == "none"
    finally:
        llm.release_resources()


LOAD = """
from emos.actors.agents.server.gguf import packaged_smollm2
from emos.actors.agents.server.llama_backend import LlamaCppResponder
LlamaCppResponder(packaged_smollm2(), n_ctx=256, n_threads=1).close()
"""


def _gomp_spincount(extra_env: dict[str, str]) -> str:
    """libgomp's spin count in a fresh process that loads the model (libgomp prints it)."""
    import os
    import re
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMP_", "GOMP_"))}
    out = subprocess.run([sys.executable, "-c", LOAD], env={**env, "OMP_DISPLAY_ENV": "VERBOSE", **extra_env},
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    match = re.search(r"GOMP_SPINCOUNT = '(\d+)'", out.stderr)
    assert match, out.stderr[-2000:]
    return match.group(1)


def test_llama_cpp_threads_sleep_at_barriers_instead_of_spinning():
    # Spinning OpenMP threads made 16 tokens take 24-45 s on 2 busy cores (1.3-3 s asleep).
    assert _gomp_spincount({}) == "0"  # libgomp's default is 300000


def test_tools_reach_a_model_whose_chat_template_has_no_tools_section():
    # SmolLM2's template drops a request's tools: without this the model never saw them.
    from emos.actors.agents.server.gguf import packaged_smollm2
    from emos.actors.agents.server.llama_backend import LlamaCppResponder
    from emos.actors.agents.types import ChatMessage, ChatRequest, ToolCall, ToolSpec

    responder = LlamaCppResponder(packaged_smollm2(), n_ctx=1024, n_threads=1)
    try:
        say = ToolSpec(name="voice__say", description="Say a sentence aloud.",
                       parameters={"type": "object", "properties": {"text": {"type": "string"}}, "required": ["text"]})
        ask = [ChatMessage(role="system", content="You are a robot."), ChatMessage(role="user", content="Say hello.")]
        bare = responder.respond(ChatRequest(messages=ask, max_tokens=1, temperature=0.0), "m")
        tooled = responder.respond(ChatRequest(messages=ask, tools=[say], max_tokens=1, temperature=0.0), "m")
        assert tooled.usage["prompt_tokens"] > bare.usage["prompt_tokens"] + 20  # the schema is in the prompt
        # An assistant turn that called a tool (no text) and the tool's answer render as text.
        history = ask + [ChatMessage(role="assistant", content=None,
                                     tool_calls=[ToolCall(id="1", name="voice__say", arguments={"text": "hello"})]),
                         ChatMessage(role="tool", content="said", tool_call_id="1", name="voice__say")]
        again = responder.respond(ChatRequest(messages=history, tools=[say], max_tokens=4, temperature=0.0), "m")
        assert again.message.role == "assistant"
        assert not responder.native_tools
    finally:
        responder.close()
