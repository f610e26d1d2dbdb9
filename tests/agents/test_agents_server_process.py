"""``emos serve models`` as a process: start-up, endpoint shapes, bad input, shutdown, restart."""
from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys

import httpx
import msgpack
import pytest

from emos.actors.agents.clients.resp import RespError, encode_command, read_reply
from emos.actors.agents.clients.sse import iter_sse_data

from .fixtures.server_process import start_server

pytestmark = pytest.mark.process


@pytest.fixture(scope="module")
def server():
    proc = start_server()
    yield proc
    assert proc.stop() == 143  # SIGTERM: a clean shutdown, then 128 + 15


@pytest.fixture()
def http(server):
    with httpx.Client(base_url=f"http://127.0.0.1:{server.port}", timeout=60) as client:
        yield client


def test_starts_fast_on_loopback(server):
    assert server.host == "127.0.0.1"
    assert server.startup_s < 15.0  # models load lazily; generous bound for a loaded 2-core machine


def test_openai_stream_framing(http):
    body = {"model": "llama3.2:3b", "stream": True, "messages": [{"role": "user", "content": "x y"}],
            "tools": [{"type": "function", "function": {"name": "go_to", "parameters": {"type": "object"}}}]}
    with http.stream("POST", "/v1/chat/completions", json=body) as response:
        assert response.headers["content-type"].startswith("text/event-stream")
        events = list(iter_sse_data(response.iter_lines()))
    assert events[-1] == "[DONE]"
    chunks = [json.loads(e) for e in events[:-1]]
    assert {c["object"] for c in chunks} == {"chat.completion.chunk"} and len({c["id"] for c in chunks}) == 1
    assert chunks[0]["choices"][0]["delta"]["role"] == "assistant"
    assert [c["choices"][0]["finish_reason"] for c in chunks if c["choices"]][-1] == "stop"
    assert chunks[-1]["choices"] == [] and chunks[-1]["usage"]["total_tokens"] > 0


def test_ollama_stream_framing(http):
    body = {"model": "llama3.2:3b", "messages": [{"role": "user", "content": "a b c"}]}  # stream defaults to true
    with http.stream("POST", "/api/chat", json=body) as response:
        lines = [json.loads(line) for line in response.iter_lines() if line]
    assert all(not line["done"] for line in lines[:-1]) and lines[-1]["done"] is True
    assert lines[-1]["done_reason"] == "stop" and "total_duration" in lines[-1]
    assert "".join(line["message"]["content"] for line in lines) == "You said: a b c"


def test_ollama_generate_and_load_unload(http):
    out = http.post("/api/generate", json={"model": "llama3.2:3b", "prompt": "hello", "stream": False}).json()
    assert out["response"] == "Hello! I am a robot." and out["done"]
    assert http.post("/api/generate", json={"model": "llama3.2:3b"}).json()["done_reason"] == "load"
    assert http.post("/api/generate", json={"model": "llama3.2:3b", "keep_alive": 0}).json()["done_reason"] == "unload"
    pieces = [json.loads(x) for x in http.post("/api/generate", json={"model": "llama3.2:3b", "prompt": "q r"}).text.splitlines()]
    assert pieces[-1]["done"] and "".join(p["response"] for p in pieces) == "You said: q r"


@pytest.mark.parametrize(
    "path, body, status",
    [
        ("/v1/chat/completions", b"{not json", 400),
        ("/v1/chat/completions", b'{"model": "emos-scripted", "messages": "hi"}', 400),
        ("/v1/chat/completions", b'{"model": "nope", "messages": [{"role": "user", "content": "x"}]}', 404),
        ("/v1/embeddings", b'{"model": "all-minilm-l6-v2", "input": []}', 400),
        ("/v1/embeddings", b'{"model": "ada-002", "input": ["x"]}', 404),
        ("/v1/audio/speech", b'{"model": "tts-1", "input": "hi", "response_format": "mp3"}', 400),
        ("/v1/audio/speech", b'{"model": "tts-1", "input": "hi", "speed": 9}', 400),
        ("/api/chat", b'{"model": "nope", "messages": [{"role": "user", "content": "x"}]}', 404),
        ("/api/chat", b'{"model": "llama3.2:3b", "messages": [{"role": "wizard", "content": "x"}]}', 400),
        ("/api/pull", b'{"model": "mistral:7b"}', 404),
        ("/api/show", b'{"model": "mistral:7b"}', 404),
        ("/api/embed", b'{"model": "nomic-embed-text", "input": "x"}', 404),
        ("/add_node?node_name=x&node_model=GPT5", b"", 400),
        ("/ghost/inference", b'{"query": "x"}', 404),
    ],
)
def test_bad_requests_get_clear_error_statuses(http, path, body, status):
    response = http.post(path, content=body, headers={"Content-Type": "application/json"})
    assert response.status_code == status
    payload = response.json()
    message = payload.get("error") or payload.get("detail")
    if isinstance(message, dict):
        message = message["message"]
    assert isinstance(message, str) and message


def test_transcription_requires_multipart(http):
    response = http.post("/v1/audio/transcriptions", json={"file": "x"})
    assert response.status_code == 400 and "multipart" in response.json()["error"]["message"]


def test_websocket_rejects_non_msgpack_frames(server):
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect

    httpx.post(f"http://127.0.0.1:{server.port}/add_node", params={"node_name": "wsbad", "node_model": "TransformersLLM"})
    with connect(f"ws://127.0.0.1:{server.port}/wsbad/ws_inference") as ws:
        ws.send("text frame")
        with pytest.raises(ConnectionClosed):  # the server closes with 1003 (unsupported data)
            ws.recv(timeout=5)
        assert ws.close_code == 1003


def resp_call(port: int, payload: bytes):
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        sock.sendall(payload)
        f = sock.makefile("rb")
        return read_reply(f.readline, f.read)


def test_resp_speaks_the_protocol(server):
    assert resp_call(server.resp_port, encode_command("PING")) == "PONG"
    assert resp_call(server.resp_port, b"PING\r\n") == "PONG"  # inline form, as redis-cli sends
    reply = resp_call(server.resp_port, encode_command("add_node", msgpack.packb({"node_name": "r1", "node_model": "Bark"})))
    assert msgpack.unpackb(reply) == {"node": "r1"}
    error = resp_call(server.resp_port, encode_command("r1.inference", msgpack.packb({"query": "hi"})))
    assert isinstance(error, RespError) and "before initialization" in str(error)
    error = resp_call(server.resp_port, encode_command("r1.inference", b"\xc1 not msgpack"))
    assert isinstance(error, RespError) and "msgpack" in str(error)
    assert isinstance(resp_call(server.resp_port, b"*1\r\n$x\r\n"), RespError)  # protocol garbage


def run_cli(*args: str, timeout: float = 30) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "emos.tools.cli", "serve", "models", *args],
                          capture_output=True, text=True, timeout=timeout)


def test_cli_reports_bad_options_clearly(tmp_path):
    done = run_cli("--port", "0", "--script", str(tmp_path / "missing.yaml"))
    assert done.returncode == 2 and "missing.yaml" in done.stderr
    gguf = tmp_path / "tiny.gguf"
    gguf.write_bytes(b"GGUF")
    done = run_cli("--port", "0", "--gguf", str(gguf))  # checked before llama.cpp is asked to open it
    assert done.returncode == 2 and "tiny.gguf" in done.stderr and "truncated" in done.stderr


def test_cli_reports_a_busy_port(server):
    done = run_cli("--port", str(server.port))
    assert done.returncode == 1 and "cannot listen" in done.stderr


def test_sigterm_with_open_connections_exits_cleanly_and_the_port_is_reusable():
    first = start_server()
    port = first.port
    # Leave a WebSocket, a RESP connection and an HTTP keep-alive connection open on purpose.
    from websockets.sync.client import connect

    httpx.post(f"http://127.0.0.1:{port}/add_node", params={"node_name": "n", "node_model": "TransformersLLM"})
    ws = connect(f"ws://127.0.0.1:{port}/n/ws_inference", legacy=True)
    resp = socket.create_connection(("127.0.0.1", first.resp_port))
    keep = httpx.Client(base_url=f"http://127.0.0.1:{port}")
    keep.get("/v1/models")
    # Exit code 143 is the server's own SIGTERM exit: open connections that held it up would get
    # it SIGKILLed at the end of this wait (a hang bound: a loaded machine takes seconds to exit).
    assert first.stop(timeout=60) == 143
    # ... and it closed them itself: the RESP peer reads end-of-stream, not a reset or a hang.
    resp.settimeout(30)
    assert resp.recv(1) == b""
    ws.close()
    resp.close()
    keep.close()
    # A chaos-style hard kill, then a restart on the same port.
    second = subprocess.Popen([sys.executable, "-m", "emos.tools.cli", "serve", "models", "--port", str(port)],
                              stdout=subprocess.PIPE, text=True)
    assert "ready" in second.stdout.readline()
    second.send_signal(signal.SIGKILL)
    second.wait(10)
    third = subprocess.Popen([sys.executable, "-m", "emos.tools.cli", "serve", "models", "--port", str(port)],
                             stdout=subprocess.PIPE, text=True)
    try:
        assert "ready" in third.stdout.readline()
        assert httpx.get(f"http://127.0.0.1:{port}/api/tags").status_code == 200
    finally:
        third.send_signal(signal.SIGTERM)
        assert third.wait(10) == 143
