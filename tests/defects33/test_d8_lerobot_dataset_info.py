"""Issue 33 D8: ``LeRobotPolicy(dataset_info_file=...)`` reads nothing when the recipe is
defined; the file is loaded at the VLA's configure from a local path, the cache
(``$XDG_CACHE_HOME/emos/lerobot/<host>/<path>``) or one download into it, and when none of them
has it the start fails with an error naming the URL and the cache file."""
from __future__ import annotations

import http.server
import shutil
import sys
import threading
from pathlib import Path

import pytest

from tests.runtime.helpers import SystemUnderTest

FIXTURE = Path(__file__).resolve().parents[1] / "agents" / "fixtures" / "lerobot_info.json"
JOINTS = {"shoulder_pan.pos": "Rotation", "shoulder_lift.pos": "Pitch", "elbow_flex.pos": "Elbow",
          "wrist_flex.pos": "Wrist_Pitch", "wrist_roll.pos": "Wrist_Roll", "gripper.pos": "Jaw"}


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    return tmp_path / "cache" / "emos" / "lerobot"


@pytest.fixture
def info_server():
    """A real HTTP server on a free port serving the fixture info.json; counts its requests."""
    body = FIXTURE.read_bytes()
    hits: list[str] = []

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self):  # noqa: N802 - http.server's name
            hits.append(self.path)
            self.send_response(200)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args):
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/datasets/pick-orange/resolve/main/meta/info.json", hits
    finally:
        server.shutdown()
        server.server_close()


def _vla(policy, cameras=("front", "wrist")):
    from emos import Topic
    from emos.actors.agents import VLA, LeRobotClient, VLAConfig

    cams = {c: Topic(name=f"cam_{c}", msg_type="Image") for c in cameras}
    return VLA(inputs=[Topic(name="joint_states", msg_type="JointState"), *cams.values()],
               outputs=[Topic(name="cmd", msg_type="JointState")], model_client=LeRobotClient(policy, port=1),
               component_name="vla", config=VLAConfig(joint_names_map=JOINTS, camera_inputs_map=cams))


_AUDIT: list[tuple[str, str]] = []
_AUDITING = threading.Event()


def _audit(event, args):
    if _AUDITING.is_set() and event in ("open", "socket.connect", "socket.getaddrinfo"):
        _AUDIT.append((event, str(args[0])))


@pytest.mark.unit
def test_defining_the_policy_and_the_vla_reads_no_file_and_opens_no_socket(cache, info_server, tmp_path):
    from emos.actors.agents import LeRobotPolicy

    url, hits = info_server
    local = tmp_path / "info.json"
    shutil.copy(FIXTURE, local)
    sys.addaudithook(_audit)  # cannot be removed; records only while _AUDITING is set
    _AUDIT.clear()
    _AUDITING.set()
    try:
        by_url = LeRobotPolicy(name="p", dataset_info_file=url)
        by_path = LeRobotPolicy(name="p", dataset_info_file=str(local))
        missing = LeRobotPolicy(name="p", dataset_info_file=str(tmp_path / "nowhere" / "info.json"))
        vlas = [_vla(by_url), _vla(by_path), _vla(missing)]
    finally:
        _AUDITING.clear()
    touched = [(e, a) for e, a in _AUDIT if "info.json" in a or str(cache) in a or e.startswith("socket")]
    assert touched == [] and hits == []
    assert all(p.dataset_info_pending and p.features == {} and p.joint_keys is None for p in (by_url, by_path, missing))
    assert len(vlas) == 3
    assert not cache.exists()


@pytest.mark.unit
def test_configure_loads_a_local_file_and_checks_it_against_the_maps(tmp_path):
    from emos.actors.agents import LeRobotPolicy

    local = tmp_path / "info.json"
    shutil.copy(FIXTURE, local)
    policy = LeRobotPolicy(name="p", dataset_info_file=str(local))
    vla = _vla(policy)
    vla.custom_on_configure()
    assert not policy.dataset_info_pending
    assert policy.joint_keys == list(JOINTS) and policy.image_keys == ["observation.images.front", "observation.images.wrist"]
    assert policy.get_init_params()["features"] is policy.features
    # the map check moved with the loading: a camera the policy needs and the map lacks
    short = _vla(LeRobotPolicy(name="p", dataset_info_file=str(local)), cameras=("front",))
    with pytest.raises(ValueError, match=r"camera_inputs_map lacks the policy's cameras \['wrist'\]"):
        short.custom_on_configure()


@pytest.mark.unit
def test_a_url_is_downloaded_once_into_the_cache_then_read_from_it_offline(cache, info_server, monkeypatch):
    from emos.actors.agents import LeRobotPolicy
    from emos.actors.agents.models.lerobot import dataset_info_cache_path

    url, hits = info_server
    cached = dataset_info_cache_path(url)
    assert cached == cache / f"127.0.0.1_{url.split(':')[2].split('/')[0]}" / "datasets" / "pick-orange" / "resolve" / "main" / "meta" / "info.json"
    first = LeRobotPolicy(name="p", dataset_info_file=url)
    _vla(first).custom_on_configure()
    assert first.joint_keys == list(JOINTS) and len(hits) == 1 and cached.read_bytes() == FIXTURE.read_bytes()
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    second = LeRobotPolicy(name="p", dataset_info_file=url)
    _vla(second).custom_on_configure()
    assert second.features == first.features and len(hits) == 1  # from the cache


@pytest.mark.unit
def test_a_path_that_escapes_is_kept_inside_the_cache(cache):
    from emos.actors.agents.models.lerobot import dataset_info_cache_path

    path = dataset_info_cache_path("https://evil.example/../../../etc/passwd?x=1")
    assert path.is_relative_to(cache) and ".." not in path.parts


@pytest.mark.unit
def test_neither_cached_nor_downloadable_fails_at_configure_naming_url_and_cache(cache, monkeypatch, tmp_path):
    from emos.actors.agents import LeRobotPolicy
    from emos.actors.agents.models.lerobot import DatasetInfoUnavailable, dataset_info_cache_path

    url = "https://huggingface.co/datasets/LightwheelAI/leisaac-pick-orange/resolve/main/meta/info.json"
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    vla = _vla(LeRobotPolicy(name="p", dataset_info_file=url))  # defining it is fine
    with pytest.raises(DatasetInfoUnavailable) as err:
        vla.custom_on_configure()
    assert url in str(err.value) and str(dataset_info_cache_path(url)) in str(err.value) and "HF_HUB_OFFLINE" in str(err.value)
    # online but unreachable (nothing listens on port 1): the same, with the reason
    monkeypatch.delenv("HF_HUB_OFFLINE")
    dead = "http://127.0.0.1:1/meta/info.json"
    with pytest.raises(DatasetInfoUnavailable, match=r"http://127.0.0.1:1/meta/info.json is not in the cache .* cannot be downloaded"):
        _vla(LeRobotPolicy(name="p", dataset_info_file=dead)).custom_on_configure()
    missing = tmp_path / "nowhere" / "info.json"
    with pytest.raises(DatasetInfoUnavailable, match=f"expected an existing info.json path or URL, got '{missing}'"):
        _vla(LeRobotPolicy(name="p", dataset_info_file=str(missing))).custom_on_configure()
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(DatasetInfoUnavailable, match="is not valid JSON"):
        _vla(LeRobotPolicy(name="p", dataset_info_file=str(bad))).custom_on_configure()


@pytest.mark.process
def test_a_run_without_the_info_file_fails_its_start_naming_the_url(tmp_path):
    url = "https://huggingface.co/datasets/LightwheelAI/leisaac-pick-orange/resolve/main/meta/info.json"
    system = SystemUnderTest(tmp_path, f"""
from emos.actors.agents import VLA, VLAConfig, LeRobotClient, LeRobotPolicy
policy = LeRobotPolicy(name="my_policy", policy_type="smolvla", checkpoint="x", dataset_info_file={url!r})
state = Topic(name="joint_states", msg_type="JointState")
cams = {{"front": Topic(name="camera", msg_type="Image"), "wrist": Topic(name="wrist_camera", msg_type="Image")}}
vla = VLA(inputs=[state, *cams.values()], outputs=[Topic(name="cmd", msg_type="JointState")],
          model_client=LeRobotClient(model=policy, port=1), component_name="vla",
          config=VLAConfig(joint_names_map={JOINTS!r}, camera_inputs_map=cams))
print("defined", flush=True)
launcher = Launcher(multi_processing=True, max_restarts=0)
launcher.add_pkg(components=[vla])
launcher.bringup()
""", env={"XDG_CACHE_HOME": str(tmp_path / "cache"), "HF_HUB_OFFLINE": "1"})
    code = system.wait_exit(timeout=120)
    out = system.output()
    assert code != 0 and "defined" in out, out[-3000:]
    assert "configure" in out and url in out and str(tmp_path / "cache" / "emos" / "lerobot" / "huggingface.co") in out, out[-3000:]
