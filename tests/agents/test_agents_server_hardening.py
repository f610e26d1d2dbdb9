"""``emos serve models`` against hostile callers, as a real process on free ports: web pages
(DNS rebinding, cross-origin simple requests), RESP peers that announce or send too much, bad
input that must give 400 rather than a 500, a taken LeRobot port, and the exit codes of
SIGINT and SIGTERM."""
from __future__ import annotations

import base64
import select
import signal
import socket
import subprocess
import sys

import httpx
import msgpack
import psutil
import pytest

from emos.actors.agents.clients import GenericHTTPClient, OllamaClient, RoboMLHTTPClient
from emos.actors.agents.clients.resp import RespError, encode_command, read_reply
from emos.actors.agents.models import GenericLLM, OllamaModel, TransformersLLM
from emos.actors.agents.types import ChatMessage, ChatRequest
from tests.runtime.helpers import wait_until

from .fixtures.server_process import READY, start_server

pytestmark = pytest.mark.process

MiB = 1024 * 1024
CHAT = {"model": "llama3.2:3b", "messages": [{"role": "user", "content": "hello"}], "stream": False}


@pytest.fixture(scope="module")
def server():
    proc = start_server()
    yield proc
    proc.stop()


@pytest.fixture()
def http(server):
    with httpx.Client(base_url=f"http://127.0.0.1:{server.port}", timeout=120) as client:
        yield client


def nodes_on(http: httpx.Client) -> list[str]:
    return http.get("/").json()["apps_served"]


# ------------------------------------------------------------------ who may call


@pytest.mark.parametrize("path", ["/v1/models", "/api/tags", "/"])
def test_a_host_that_is_not_this_machine_is_refused(http, path):
    # DNS rebinding: a page of evil.example whose name now resolves to 127.0.0.1.
    response = http.get(path, headers={"Host": "evil.example"})
    assert response.status_code == 403
    assert "this machine only" in response.text
    response = http.post("/add_node", params={"node_name": "rebound", "node_model": "Bark"},
                         headers={"Host": "evil.example:8000"})
    assert response.status_code == 403 and "rebound" not in nodes_on(http)


@pytest.mark.parametrize("origin", ["null", "https://evil.example", "http://evil.example:8000", "http://127.0.0.1:1"])
def test_a_foreign_origin_is_refused(http, origin):
    response = http.post("/v1/chat/completions", json=CHAT, headers={"Origin": origin})
    assert response.status_code == 403 and "cross-origin" in response.json()["error"]["message"]
    response = http.post("/add_node", params={"node_name": "crossed", "node_model": "Bark"}, headers={"Origin": origin})
    assert response.status_code == 403 and "crossed" not in nodes_on(http)


def test_the_servers_own_origin_is_accepted(http, server):
    response = http.post("/v1/chat/completions", json=CHAT, headers={"Origin": f"http://127.0.0.1:{server.port}"})
    assert response.status_code == 200


@pytest.mark.parametrize("path", ["/v1/chat/completions", "/api/chat", "/v1/embeddings", "/api/generate"])
@pytest.mark.parametrize("content_type", ["text/plain", "application/x-www-form-urlencoded"])
def test_a_simple_cross_origin_style_post_cannot_reach_json_routes(http, path, content_type):
    # What a page can send without a CORS preflight: a JSON text under a "simple" content type.
    body = b'{"model": "llama3.2:3b", "messages": [{"role": "user", "content": "hello"}], "prompt": "hi", "input": "x"}'
    response = http.post(path, content=body, headers={"Content-Type": content_type})
    assert 400 <= response.status_code < 500
    assert "application/json" in response.text


def test_add_node_refuses_a_form_body(http):
    response = http.post("/add_node?node_name=formed&node_model=Bark", content=b"a=b",
                         headers={"Content-Type": "text/plain"})
    assert response.status_code == 415 and "formed" not in nodes_on(http)


def test_the_projects_own_clients_still_work(server):
    openai = GenericHTTPClient(GenericLLM(name="llm", checkpoint="emos-scripted"), port=server.port)
    ollama = OllamaClient(OllamaModel(name="llama", checkpoint="llama3.2:3b"), port=server.port)
    roboml = RoboMLHTTPClient(TransformersLLM(name="hardened"), port=server.port)
    try:
        request = ChatRequest(messages=[ChatMessage("user", "hello")])
        for client in (openai, ollama, roboml):
            client.check_connection()
            client.initialize()
            assert client.inference(request).message.content == "Hello! I am a robot."
            client.deinitialize()
    finally:
        for client in (openai, ollama, roboml):
            client.close()


# ------------------------------------------------------------------ bad input: 400, not 500


@pytest.mark.parametrize("path", ["/v1/chat/completions", "/api/chat", "/v1/embeddings", "/api/show"])
def test_deeply_nested_json_is_a_400_that_says_why(http, path):
    response = http.post(path, content=b"[" * 100_000, headers={"Content-Type": "application/json"})
    assert response.status_code == 400
    assert "nested too deeply" in response.text


def test_deeply_nested_json_to_a_roboml_node_is_a_400(http):
    assert http.post("/add_node", params={"node_name": "deep", "node_model": "TransformersLLM"}).status_code in (200, 201)
    response = http.post("/deep/inference", content=b'{"query": ' + b"[" * 100_000,
                         headers={"Content-Type": "application/json"})
    assert response.status_code == 400 and "nested too deeply" in response.json()["detail"]


@pytest.mark.parametrize("audio", [b"RIFF\x24\x00\x00\x00WAVEgarbage that is not a wave file", b"ID3\x03 an mp3"])
def test_an_upload_that_is_not_wav_is_a_400_that_says_why(http, audio):
    response = http.post("/v1/audio/transcriptions", files={"file": ("speech.wav", audio, "audio/wav")},
                         data={"model": "whisper-1"})
    assert response.status_code == 400
    assert "WAV" in response.json()["error"]["message"]


def test_a_roboml_speech_node_given_non_wav_audio_is_a_400(http):
    http.post("/add_node", params={"node_name": "ears", "node_model": "Whisper"})
    assert http.post("/ears/initialize", json={}).status_code == 200
    query = base64.b64encode(b"RIFF\x24\x00\x00\x00WAVEgarbage").decode()
    response = http.post("/ears/inference", json={"query": query})
    assert response.status_code == 400 and "WAV" in response.json()["detail"]


@pytest.mark.parametrize("body", [{"model": ["x"], "messages": []}, {"model": "llama3.2:3b", "messages": [1]}])
def test_malformed_ollama_chat_is_a_400(http, body):
    assert http.post("/api/chat", json=body).status_code == 400


@pytest.mark.parametrize("path, body", [
    ("/api/generate", {"model": ["x"], "prompt": "hi"}),
    ("/api/show", {"model": {"a": 1}}),
    ("/api/pull", {"model": ["x"]}),
    ("/v1/audio/speech", {"model": "tts-1", "input": "hi", "voice": ["x"]}),
])
def test_wrongly_typed_fields_are_a_400(http, path, body):
    response = http.post(path, json=body)
    assert response.status_code == 400, response.text


@pytest.mark.parametrize("path, model", [("/v1/embeddings", "all-minilm-l6-v2"), ("/api/embed", "all-minilm")])
def test_embedding_inputs_are_bounded(http, path, model):
    response = http.post(path, json={"model": model, "input": ["x"] * 5000})
    assert response.status_code == 400 and "at most 2048" in response.text
    response = http.post(path, json={"model": model, "input": ["y" * 600_000, "z" * 600_000]})
    assert response.status_code == 400 and "characters" in response.text


# ------------------------------------------------------------------ RESP memory


def rss(server) -> int:
    return psutil.Process(server.process.pid).memory_info().rss


def resp_call(port: int, payload: bytes):
    with socket.create_connection(("127.0.0.1", port), timeout=60) as sock:
        sock.sendall(payload)
        f = sock.makefile("rb")
        return read_reply(f.readline, f.read)


def push_until_answered(sock: socket.socket, header: bytes, size: int, stop_before_end: int = 0) -> object | None:
    """Send ``header`` then up to ``size - stop_before_end`` payload bytes (and the closing CRLF if
    all ``size`` went), stopping early when the server answers or closes. Returns the reply, or
    None if the server has not answered yet."""
    sock.sendall(header)
    chunk = b"\0" * MiB
    sent = 0
    while sent < size - stop_before_end:
        readable, _, _ = select.select([sock], [], [], 0)
        if readable:
            break
        try:
            sent += sock.send(chunk[: min(len(chunk), size - stop_before_end - sent)])
        except OSError:
            break
    if sent == size:  # the whole bulk string went through: terminate it
        sock.sendall(b"\r\n")
    readable, _, _ = select.select([sock], [], [], 0)
    if not readable:
        return None
    f = sock.makefile("rb")
    try:
        return read_reply(f.readline, f.read)
    except (OSError, EOFError):
        return EOFError("closed without a reply")


def test_resp_refuses_huge_announcements_without_growing(server):
    before = rss(server)
    # 200 MiB announced and sent (the old server buffered up to 256 MiB per argument, 64 of them).
    with socket.create_connection(("127.0.0.1", server.resp_port), timeout=60) as sock:
        reply = push_until_answered(sock, b"*2\r\n$4\r\nPING\r\n$%d\r\n" % (200 * MiB), 200 * MiB)
        if reply is None:  # still reading: let it finish and answer
            f = sock.makefile("rb")
            reply = read_reply(f.readline, f.read)
    assert rss(server) - before < 64 * MiB
    assert isinstance(reply, RespError) and "64 MiB" in str(reply), reply
    # One command announcing 1 GiB: refused at the header, nothing allocated.
    with socket.create_connection(("127.0.0.1", server.resp_port), timeout=60) as sock:
        sock.sendall(b"*2\r\n$4\r\nPING\r\n$1073741824\r\n")
        f = sock.makefile("rb")
        reply = read_reply(f.readline, f.read)
    assert isinstance(reply, RespError) and "64 MiB" in str(reply)
    assert rss(server) - before < 64 * MiB
    assert resp_call(server.resp_port, encode_command("PING")) == "PONG"


def test_resp_bounds_the_bytes_in_flight_across_connections(server):
    """Ten peers each start a 60 MiB command and stall before its end. The server holds at most
    its 256 MiB budget; the others are told it is busy; other clients are still served."""
    before = rss(server)
    peers: list[socket.socket] = []
    replies: list[object | None] = []
    try:
        for _ in range(10):
            sock = socket.create_connection(("127.0.0.1", server.resp_port), timeout=60)
            peers.append(sock)
            replies.append(push_until_answered(sock, b"*2\r\n$4\r\nPING\r\n$%d\r\n" % (60 * MiB), 60 * MiB,
                                               stop_before_end=1))
        busy = [r for r in replies if isinstance(r, RespError) and "server busy" in str(r)]
        assert busy, replies
        assert rss(server) - before < 400 * MiB  # the budget (256 MiB) plus slack; 600 MiB unbounded
        assert resp_call(server.resp_port, encode_command("PING")) == "PONG"
        assert httpx.get(f"http://127.0.0.1:{server.port}/v1/models", timeout=60).status_code == 200
    finally:
        for sock in peers:
            sock.close()
    # The closed peers' bytes are given back: a 60 MiB command gets through again.

    def big_ping() -> bool:
        with socket.create_connection(("127.0.0.1", server.resp_port), timeout=60) as sock:
            reply = push_until_answered(sock, b"*2\r\n$4\r\nPING\r\n$%d\r\n" % (60 * MiB), 60 * MiB)
            if reply is None:
                f = sock.makefile("rb")
                reply = read_reply(f.readline, f.read)
        return reply == "PONG"

    wait_until(big_ping, timeout=120, interval=0.2, what="the RESP budget to be given back")
    payload = msgpack.packb({"node_name": "after", "node_model": "Bark"})
    assert msgpack.unpackb(resp_call(server.resp_port, encode_command("add_node", payload))) == {"node": "after"}


def test_an_http_request_on_the_resp_port_runs_nothing(server, http):
    # A web page can POST to any port; its body can be RESP (a cross-protocol request).
    command = encode_command("add_node", msgpack.packb({"node_name": "smuggled", "node_model": "Bark"}))
    request = (b"POST / HTTP/1.1\r\nHost: 127.0.0.1:%d\r\nContent-Type: text/plain\r\n"
               b"Content-Length: %d\r\n\r\n" % (server.resp_port, len(command))) + command
    with socket.create_connection(("127.0.0.1", server.resp_port), timeout=60) as sock:
        sock.sendall(request)
        sock.shutdown(socket.SHUT_WR)
        answer = sock.makefile("rb").read()  # until the server closes
    assert answer.startswith(b"-ERR") and b"only PING may be sent inline" in answer
    assert "smuggled" not in nodes_on(http)
    assert resp_call(server.resp_port, b"PING\r\n") == "PONG"  # what redis-cli sends inline still works


# ------------------------------------------------------------------ ports and signals


@pytest.mark.parametrize("option, name", [("--lerobot-port", "LeRobot"), ("--resp-port", "RESP"), ("--port", "HTTP")])
def test_a_taken_port_is_named_in_one_line_and_fails(option, name):
    taken = socket.socket()
    taken.bind(("127.0.0.1", 0))
    taken.listen()
    port = taken.getsockname()[1]
    args = {"--port": "0", option: str(port)}
    try:
        done = subprocess.run([sys.executable, "-m", "emos.tools.cli", "serve", "models",
                               *[word for pair in args.items() for word in pair]],
                              capture_output=True, text=True, timeout=120)
    finally:
        taken.close()
    assert done.returncode == 1
    assert done.stderr == f"emos serve models: cannot listen on 127.0.0.1:{port} for the {name} server: address in use\n"


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_signals_end_it_cleanly_with_the_shell_exit_code(sig, code):
    proc = subprocess.Popen([sys.executable, "-m", "emos.tools.cli", "serve", "models", "--port", "0",
                             "--resp-port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    held = None
    try:
        ready = proc.stdout.readline()
        match = READY.search(ready)
        assert match, ready + proc.stderr.read()
        # An open RESP connection and a finished request: shutdown must still be clean.
        held = socket.create_connection(("127.0.0.1", int(match.group(3))), timeout=30)
        assert httpx.get(f"http://127.0.0.1:{match.group(2)}/api/tags", timeout=60).status_code == 200
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        if held is not None:
            held.close()
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == code, err
    assert "Traceback" not in err, err
