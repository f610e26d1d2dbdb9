"""Issue 40 item 1, bad input: a GGUF file that is missing or corrupt is refused at start with an
error naming the file (the recipe line, `emos serve models`), never by llama.cpp later; the local
model's config is validated on set; the packaged SmolLM2 is found without a download."""
from __future__ import annotations

import struct

import pytest

from emos.actors.agents.components.llm import LLM, LLMConfig
from emos.actors.agents.components.mllm import VLM
from emos.actors.agents.server.gguf import LocalModelError, check_gguf, packaged_smollm2
from emos.actors.agents.server.local_client import LOCAL_CLIENT, LocalLLM, LocalLLMClient
from emos.io.topic import Topic

pytestmark = pytest.mark.unit

Q = Topic(name="q", msg_type="String")
A = Topic(name="a", msg_type="String")
IMG = Topic(name="img", msg_type="Image")


def _gguf(path, version=3, tensors=10, keys=5, body=b"\0" * 64):
    path.write_bytes(b"GGUF" + struct.pack("<IQQ", version, tensors, keys) + body)
    return path


@pytest.mark.parametrize("make, problem", [
    (lambda p: p, "does not exist"),
    (lambda p: (p.mkdir(), p)[1], "is not a file"),
    (lambda p: (p.write_bytes(b"GGUF\x03\0"), p)[1], "is truncated"),
    (lambda p: (p.write_bytes(b"<html>not found</html>" * 4), p)[1], "is not a GGUF file"),
    (lambda p: _gguf(p, version=1), "GGUF version 1"),
    (lambda p: _gguf(p, tensors=0), "corrupt header"),
    (lambda p: _gguf(p, keys=1 << 40), "corrupt header"),
], ids=["missing", "directory", "truncated", "not-gguf", "old-version", "no-tensors", "absurd-keys"])
def test_bad_gguf_files_are_refused_with_the_file_named(tmp_path, make, problem):
    path = make(tmp_path / "model.gguf")
    with pytest.raises(LocalModelError, match=problem) as info:
        check_gguf(path)
    assert str(tmp_path / "model.gguf") in str(info.value)


def test_the_packaged_model_is_found_and_is_a_gguf_file():
    path = packaged_smollm2()
    assert path.name == "SmolLM2-135M-Instruct.Q4_1.gguf" and check_gguf(path) == path


def test_a_recipe_line_with_a_corrupt_local_model_names_the_component_and_the_file(tmp_path):
    bad = tmp_path / "broken.gguf"
    bad.write_bytes(b"\0" * 100)
    with pytest.raises(ValueError, match=r"component 'talker': local model: GGUF model '.*broken\.gguf' is not a GGUF file"):
        LLM(inputs=[Q], outputs=[A], trigger=Q, component_name="talker", enable_local_model=True,
            config=LLMConfig(local_model_path=str(bad)))
    with pytest.raises(ValueError, match="missing.gguf' does not exist"):
        VLM(inputs=[Q, IMG], outputs=[A], trigger=Q, component_name="eyes",
            config=LLMConfig(enable_local_model=True, local_model_path=str(tmp_path / "missing.gguf")))


def test_local_model_config_is_checked_when_set():
    with pytest.raises(ValueError, match="LLMConfig.ncpu_local_model"):
        LLMConfig(ncpu_local_model=0)
    with pytest.raises(ValueError, match="LLMConfig.local_model_context"):
        LLMConfig(local_model_context=16)
    with pytest.raises(ValueError, match="LLMConfig.local_model_path must be None"):
        LLMConfig(local_model_path="  ")
    with pytest.raises(TypeError, match="enable_local_model must be True or False"):
        LLM(inputs=[Q], outputs=[A], trigger=Q, component_name="x", enable_local_model="yes")
    with pytest.raises(ValueError, match="needs a model_client"):  # neither a server nor the local model
        LLM(inputs=[Q], outputs=[A], trigger=Q, component_name="x")


def test_local_model_is_the_primary_without_a_server_and_a_standby_with_one():
    alone = LLM(inputs=[Q], outputs=[A], trigger=Q, component_name="alone", enable_local_model=True)
    assert isinstance(alone.model_client, LocalLLMClient) and alone.additional_model_clients == {}
    from emos.actors.agents.clients import OllamaClient
    from emos.actors.agents.models import OllamaModel

    server = OllamaClient(OllamaModel(name="m", checkpoint="x"), port=9)
    both = LLM(inputs=[Q], outputs=[A], trigger=Q, component_name="both", model_client=server,
               config=LLMConfig(enable_local_model=True))
    assert both.model_client is server and isinstance(both.additional_model_clients[LOCAL_CLIENT], LocalLLMClient)
    both.additional_model_clients = {"backup": OllamaClient(OllamaModel(name="b", checkpoint="x"), port=10)}
    assert set(both.additional_model_clients) == {"backup", LOCAL_CLIENT}  # the local model stays


def test_local_client_survives_serialization_and_copies():
    import copy

    from emos.actors.agents.clients import client_from_serialized

    client = LocalLLMClient(LocalLLM(n_threads=1, n_ctx=512))
    again = client_from_serialized(client.serialize())
    assert isinstance(again, LocalLLMClient) and again.path == client.path and again.model.n_ctx == 512
    assert copy.deepcopy(client).model == client.model and not copy.deepcopy(client).loaded
