"""Model specs: spec defaults, validation at definition time, dict round trip."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from emos.actors.agents.models import (
    MODEL_TYPES,
    Bark,
    GenericLLM,
    GenericMLLM,
    GenericSTT,
    GenericTTS,
    LeRobotPolicy,
    MeloTTS,
    OllamaModel,
    RoboBrain2,
    SpeechT5,
    TransformersLLM,
    TransformersMLLM,
    VisionModel,
    Whisper,
    features_from_dataset_info,
    model_from_dict,
)

pytestmark = pytest.mark.unit

FIXTURES = Path(__file__).parent / "fixtures"

ALL = [GenericLLM, GenericMLLM, GenericTTS, GenericSTT, OllamaModel, TransformersLLM, TransformersMLLM,
       LeRobotPolicy, RoboBrain2, Whisper, SpeechT5, Bark, MeloTTS, VisionModel]


def test_every_spec_model_is_registered_by_name():
    assert {cls.__name__ for cls in ALL} <= set(MODEL_TYPES)


@pytest.mark.parametrize(
    "cls, defaults",
    [
        (GenericLLM, {"checkpoint": "gpt-4o", "options": None}),
        (GenericTTS, {"checkpoint": "tts-1", "voice": "alloy", "speed": 1.0}),
        (GenericSTT, {"checkpoint": "whisper-1", "temperature": 0.0, "language": None}),
        (OllamaModel, {"checkpoint": "llama3.2:3b", "options": None}),
        (TransformersLLM, {"quantization": "4bit"}),
        (TransformersMLLM, {"checkpoint": "HuggingFaceM4/idefics2-8b", "quantization": "4bit"}),
        (RoboBrain2, {"checkpoint": "BAAI/RoboBrain2.0-7B"}),
        (Whisper, {"checkpoint": "small.en", "compute_type": "int8"}),
        (SpeechT5, {"checkpoint": "microsoft/speecht5_tts", "voice": "clb"}),
        (Bark, {"checkpoint": "suno/bark-small", "voice": "v2/en_speaker_6"}),
        (MeloTTS, {"language": "EN", "speaker_id": "EN-US"}),
        (VisionModel, {"checkpoint": "dino-4scale_r50_8xb2-12e_coco", "setup_trackers": False,
                       "tracking_distance_threshold": 30, "deploy_tensorrt": False}),
        (LeRobotPolicy, {"checkpoint": "lerobot/smolvla_base", "policy_type": "smolvla", "actions_per_chunk": 50}),
    ],
)
def test_defaults_match_the_spec(cls, defaults):
    model = cls(name="m")
    for field, value in defaults.items():
        assert getattr(model, field) == value, field
    assert model.init_timeout is None


@pytest.mark.parametrize("cls", ALL)
def test_round_trip_through_a_plain_dict(cls):
    model = cls(name="m", init_timeout=5)
    data = json.loads(json.dumps(model.to_dict()))  # must survive JSON (and hence msgpack)
    rebuilt = model_from_dict(data)
    assert type(rebuilt) is cls and rebuilt == model
    assert rebuilt.get_init_params() == model.get_init_params()


def test_recipe_style_construction():
    qwen = OllamaModel(name="qwen_vl", checkpoint="qwen2.5vl:latest")
    assert qwen.get_init_params() == {"checkpoint": "qwen2.5vl:latest", "options": None}
    melo = MeloTTS(name="melo1", language="JP", speaker_id="JP-1")
    assert melo.get_init_params() == {"language": "JP", "speaker_id": "JP-1"}
    vision = VisionModel(name="det", num_trackers=2, setup_trackers=True)
    assert vision.get_init_params()["num_trackers"] == 2


@pytest.mark.parametrize(
    "build, message",
    [
        (lambda: OllamaModel(name="x", options={"temprature": 0.5}), "unknown option 'temprature'"),
        (lambda: OllamaModel(name="x", options={"num_predict": "many"}), "expected int"),
        (lambda: OllamaModel(name="x", options={"stop": "END"}), "list of strings"),
        (lambda: GenericLLM(name="x", options={"seed": True}), "got bool"),
        (lambda: GenericTTS(name="x", speed=5.0), "[0.25, 4.0]"),
        (lambda: GenericSTT(name="x", language="english"), "ISO-639-1"),
        (lambda: GenericSTT(name="x", temperature=1.5), "[0, 1]"),
        (lambda: TransformersLLM(name="x", quantization="2bit"), "quantization"),
        (lambda: Whisper(name="x", checkpoint="gigantic"), "Whisper.checkpoint"),
        (lambda: SpeechT5(name="x", voice="bob"), "voice"),
        (lambda: MeloTTS(name="x", language="JP", speaker_id="EN-US"), "speaker of language 'JP'"),
        (lambda: VisionModel(name="x", tracking_distance_threshold=0), "tracking_distance_threshold"),
        (lambda: LeRobotPolicy(name="x", policy_type="gpt"), "policy_type"),
        (lambda: LeRobotPolicy(name="x", actions_per_chunk=0), "actions_per_chunk"),
        (lambda: GenericLLM(name=""), "non-empty string"),
        (lambda: GenericLLM(name="x", init_timeout=-1), "init_timeout"),
    ],
)
def test_bad_values_fail_at_definition_time_with_a_clear_message(build, message):
    with pytest.raises((ValueError, TypeError)) as info:
        build()
    assert message in str(info.value)


def test_validation_also_runs_when_a_field_is_set_later():
    tts = GenericTTS(name="t")
    with pytest.raises(ValueError, match="speed"):
        tts.speed = 10.0
    assert tts.speed == 1.0


def test_unknown_model_type_in_a_dict_is_rejected():
    with pytest.raises(ValueError, match="unknown model_type 'GPT5'"):
        model_from_dict({"model_type": "GPT5", "name": "x"})


def test_lerobot_policy_reads_features_from_a_dataset_info_file():
    policy = LeRobotPolicy(name="arm", dataset_info_file=str(FIXTURES / "lerobot_info.json"), policy_device="cpu")
    assert policy.dataset_info_pending and policy.image_keys is None  # defining it reads nothing (issue 33 D8)
    policy.load_dataset_info()  # what the VLA's configure does
    assert policy.image_keys == ["observation.images.front", "observation.images.wrist"]
    assert policy.joint_keys[0] == "shoulder_pan.pos" and len(policy.joint_keys) == 6
    assert set(policy.features) == {"observation.state", "observation.images.front", "observation.images.wrist"}
    assert policy.actions["shape"] == [6]
    params = policy.get_init_params()
    assert params["features"] is policy.features and params["device"] == "cpu"
    # Rebuilt in another process from its dict, it must not need the file again.
    data = policy.to_dict()
    data["dataset_info_file"] = "/nonexistent/info.json"
    assert model_from_dict(data).joint_keys == policy.joint_keys


def test_lerobot_policy_rejects_a_missing_or_malformed_info_file(tmp_path):
    # When the file is loaded (the VLA's configure), not when the policy is defined.
    with pytest.raises(ValueError, match="existing info.json"):
        LeRobotPolicy(name="arm", dataset_info_file=str(tmp_path / "missing.json")).load_dataset_info()
    bad = tmp_path / "info.json"
    bad.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        LeRobotPolicy(name="arm", dataset_info_file=str(bad)).load_dataset_info()
    with pytest.raises(ValueError, match="'action'"):
        features_from_dataset_info({"features": {"observation.state": {"names": ["a"]}}})
