"""Model faults seen by components: a server dying mid-stream, garbage answers, malformed tool
calls, the primary killed while running (hot swap to the backup)."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from emos import msgs as M
from tests.agents.components_helpers import AGENT_HEADER, Probe
from tests.agents.fixtures.server_process import start_server
from tests.agents.fixtures.stub_servers import ScriptedHTTP
from tests.runtime.helpers import SystemUnderTest, wait_until

pytestmark = pytest.mark.process

FIXTURES = Path(__file__).parent / "fixtures"
MODELS = (200, "application/json", json.dumps({"object": "list", "data": [{"id": "m", "object": "model"}]}).encode())


def _sse(*pieces: str) -> bytes:
    chunks = [{"id": "c", "object": "chat.completion.chunk", "choices": [{"index": 0, "delta": {"content": p}, "finish_reason": None}]}
              for p in pieces]
    return "".join(f"data: {json.dumps(c)}\n\n" for c in chunks).encode()  # no finish_reason, no [DONE]: cut off


def test_stream_cut_mid_answer_publishes_only_complete_pieces(tmp_path):
    stub = ScriptedHTTP({("GET", "/v1/models"): MODELS,
                         ("POST", "/v1/chat/completions"): (200, "text/event-stream",
                                                            _sse("First sentence. Sec", "ond sentence. Third un"))})
    system = SystemUnderTest(tmp_path, AGENT_HEADER + f"""
client = GenericHTTPClient(GenericLLM(name="m", checkpoint="m"), port={stub.port})
q = Topic(name="q", msg_type="String")
a = Topic(name="a", msg_type="String")
s = Topic(name="s", msg_type="StreamingString")
llm = LLM(inputs=[q], outputs=[a, s], model_client=client, trigger=q, component_name="talker",
          config=LLMConfig(stream=True))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[llm])
launcher.bringup()
""", duration=60).wait_up(components=["talker"], timeout=60)
    probe = Probe(system)
    try:
        probe.sub("/a", "String"), probe.sub("/s", "StreamingString")
        probe.pub("/q", M.String(data="tell me"))
        assert [m.data for m in probe.collect("/a", "String", 2)] == ["First sentence.", "Second sentence."]
        wait_until(lambda: probe.status("talker").status == M.ComponentStatus.STATUS_FAILURE_ALGORITHM_LEVEL, 15,
                   what="the broken stream reported")
        assert "stream broke after 2 piece(s)" in probe.status("talker").message
        streamed = probe.collect("/s", "StreamingString", 2)
        assert all(not m.done for m in streamed)  # never marked complete
        assert probe.drain("/a", "String") == [] and probe.drain("/s", "StreamingString") == []  # "Third un" never goes out
        assert stub.hits[("POST", "/v1/chat/completions")] == 1  # text went out: no re-send that would repeat it
    finally:
        probe.close()
        assert system.stop() == 0
        stub.close()


def test_garbage_answers_and_malformed_tool_calls_are_algorithm_failures(tmp_path):
    garbage = ScriptedHTTP({("GET", "/v1/models"): MODELS,
                            ("POST", "/v1/chat/completions"): (200, "application/json", b"\x00not json at all")})
    bad_tool = ScriptedHTTP({("GET", "/v1/models"): MODELS,
                             ("POST", "/v1/chat/completions"): (200, "application/json",
                                                                (FIXTURES / "openai_chat_response_bad_arguments.json").read_bytes())})
    system = SystemUnderTest(tmp_path, AGENT_HEADER + f"""
q = Topic(name="q", msg_type="String")
junk = LLM(inputs=[q], outputs=[Topic(name="junk_out", msg_type="String")], trigger=q, component_name="junk",
           model_client=GenericHTTPClient(GenericLLM(name="m", checkpoint="m"), port={garbage.port}))
tools = LLM(inputs=[q], outputs=[Topic(name="tool_out", msg_type="String")], trigger=q, component_name="tools",
            model_client=GenericHTTPClient(GenericLLM(name="m", checkpoint="m"), port={bad_tool.port}))
def go_to(place: str) -> str:
    return place
def say(text: str, volume: float) -> str:
    return text
tools.register_tool(go_to, {{"type": "function", "function": {{"name": "go_to", "parameters": {{"type": "object",
                    "properties": {{"place": {{"type": "string"}}}}, "required": ["place"]}}}}}})
tools.register_tool(say, {{"type": "function", "function": {{"name": "say", "parameters": {{"type": "object",
                    "properties": {{"text": {{"type": "string"}}, "volume": {{"type": "number"}}}}}}}}}})
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[junk, tools])
launcher.bringup()
""", duration=60).wait_up(components=["junk", "tools"], timeout=60)
    probe = Probe(system)
    try:
        probe.sub("/junk_out", "String"), probe.sub("/tool_out", "String")
        pids = {c: system.pid(c) for c in ("junk", "tools")}
        probe.pub("/q", M.String(data="hello"))
        for name in ("junk", "tools"):
            wait_until(lambda name=name: probe.status(name).status == M.ComponentStatus.STATUS_FAILURE_ALGORITHM_LEVEL, 15,
                       what=f"{name} to report an algorithm failure")
            assert "MalformedResponseError" in probe.status(name).message
        assert "tool-call arguments" in probe.status("tools").message
        assert probe.drain("/junk_out", "String") == [] and probe.drain("/tool_out", "String") == []
        # model_failover_after=2: the request was tried twice, then given up (no backup).
        assert garbage.hits[("POST", "/v1/chat/completions")] == 2
        assert {c: system.pid(c) for c in pids} == pids
    finally:
        probe.close()
        assert system.stop() == 0
        garbage.close()
        bad_tool.close()


def test_primary_killed_while_running_swaps_to_the_backup(tmp_path, model_server):
    primary = start_server(script=str(Path(__file__).parent / "data" / "primary_script.yaml"))
    system = SystemUnderTest(tmp_path, AGENT_HEADER + f"""
primary = OllamaClient(OllamaModel(name="primary", checkpoint="llama3.2:3b"), port={primary.port})
backup = OllamaClient(OllamaModel(name="backup", checkpoint="llama3.2:3b"), port={model_server.port})
q = Topic(name="q", msg_type="String")
a = Topic(name="a", msg_type="String")
brain = LLM(inputs=[q], outputs=[a], model_client=primary, trigger=q, component_name="brain")
brain.additional_model_clients = {{"local_backup_client": backup}}
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[brain])
launcher.bringup()
""", duration=90).wait_up(components=["brain"], timeout=60)
    probe = Probe(system)
    try:
        probe.sub("/a", "String")
        probe.pub("/q", M.String(data="one"))
        assert probe.collect("/a", "String")[0].data == "primary says: one"
        primary.stop()
        probe.pub("/q", M.String(data="two"))
        assert probe.collect("/a", "String")[0].data == "You said: two"  # the same request, answered by the backup
        probe.pub("/q", M.String(data="three"))
        assert probe.collect("/a", "String")[0].data == "You said: three"
        wait_until(lambda: probe.status("brain").status == M.ComponentStatus.STATUS_HEALTHY, 10, what="healthy on the backup")
    finally:
        probe.close()
        primary.stop()
        assert system.stop() == 0


def test_a_silent_server_times_out_while_the_heartbeat_keeps_beating(tmp_path):
    from tests.agents.fixtures.stub_servers import RawServer, silent

    stub = RawServer(silent)  # accepts, reads, never answers
    system = SystemUnderTest(tmp_path, AGENT_HEADER + f"""
q = Topic(name="q", msg_type="String")
slow = LLM(inputs=[q], outputs=[Topic(name="a", msg_type="String")], trigger=q, component_name="slow",
           model_client=GenericHTTPClient(GenericLLM(name="m", checkpoint="m"), port={stub.port}, inference_timeout=3))
launcher = Launcher(multi_processing=True, heartbeat_timeout=2.0)
launcher.add_pkg(components=[slow])
launcher.bringup()
""", duration=60).wait_up(components=["slow"], timeout=60)
    probe = Probe(system)
    try:
        pid = system.pid("slow")
        probe.pub("/q", M.String(data="hello"))
        wait_until(lambda: "ModelTimeoutError" in probe.status("slow").message, 20, what="the timeout reported")
        assert probe.status("slow").status == M.ComponentStatus.STATUS_FAILURE_COMPONENT_LEVEL
        import time
        time.sleep(4.0)  # longer than the heartbeat timeout, while requests keep timing out
        assert system.pid("slow") == pid  # never killed as hung
        assert "missed its heartbeat" not in system.output()
    finally:
        probe.close()
        assert system.stop() == 0
        stub.close()
