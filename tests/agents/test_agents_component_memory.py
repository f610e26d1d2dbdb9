"""SemanticRouter, MapEncoding (real Chroma) and VideoMessageMaker as real processes."""
from __future__ import annotations

import numpy as np
import pytest

from emos import msgs as M
from tests.agents.components_helpers import AGENT_HEADER, Probe
from tests.runtime.helpers import SystemUnderTest, wait_until

pytestmark = pytest.mark.process

HEADER = AGENT_HEADER + """
from emos.actors.agents import (SemanticRouter, SemanticRouterConfig, Route, MapEncoding, MapConfig, MapLayer,
                                VideoMessageMaker, VideoMessageMakerConfig, ChromaClient, ChromaDB)
"""


def _grid(resolution=0.5):
    info = M.MapMetaData(resolution=resolution, width=20, height=20)
    return M.OccupancyGrid(info=info, data=np.zeros(400, np.int8))


def _odom(x, y):
    odom = M.Odometry()
    odom.pose.pose.position.x, odom.pose.pose.position.y = x, y
    return odom


def test_router_vector_and_llm_modes_route_and_fall_back_to_default(tmp_path, model_server):
    system = SystemUnderTest(tmp_path, HEADER + f"""
query = Topic(name="question", msg_type="String")
query2 = Topic(name="question2", msg_type="String")
goto_in = Topic(name="goto_in", msg_type="String")
llm_in = Topic(name="text_in_llm", msg_type="String")
goto_route = Route(routes_to=goto_in, samples=["Go to the door", "Go to the kitchen", "Get me a glass", "Fetch a ball"])
llm_route = Route(routes_to=llm_in, samples=["What is the capital of France?", "Is there life on Mars?", "How are you today?"])
# Embeddings come from the local server (as from an Ollama server): no torch in the component.
chroma = ChromaClient(db=ChromaDB(path={str(tmp_path / "chroma")!r}, embeddings="ollama", checkpoint="all-minilm",
                                  ollama_port={model_server.port}))
router = SemanticRouter(inputs=[query], routes=[llm_route, goto_route], default_route=llm_route, db_client=chroma,
                        config=SemanticRouterConfig(router_name="go-to-router", distance_func="l2"), component_name="router")
llm_client = OllamaClient(OllamaModel(name="llama", checkpoint="llama3.2:3b"), port={model_server.port})
smart = SemanticRouter(inputs=[query2], routes=[llm_route, goto_route], default_route=llm_route,
                       model_client=llm_client, component_name="smart_router")
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[router, smart])
launcher.bringup()
""", duration=120).wait_up(components=["router", "smart_router"], timeout=60)
    probe = Probe(system)
    try:
        probe.sub("/goto_in", "String"), probe.sub("/text_in_llm", "String")
        wait_until(lambda: probe.status("router").status == M.ComponentStatus.STATUS_HEALTHY, 60, what="router ready")
        probe.pub("/question", M.String(data="please walk over to the kitchen"))
        assert probe.collect("/goto_in", "String")[0].data == "please walk over to the kitchen"
        probe.pub("/question", M.String(data="what is the capital of Italy?"))
        assert probe.collect("/text_in_llm", "String")[0].data == "what is the capital of Italy?"
        # Far from every sample (beyond maximum_distance): the default route.
        probe.pub("/question", M.String(data="zxqv 1234 lorem ipsum"))
        assert probe.collect("/text_in_llm", "String")[0].data == "zxqv 1234 lorem ipsum"
        assert probe.drain("/goto_in", "String") == []
        # LLM mode: the scripted model calls no route tool, so the default route gets it.
        probe.pub("/question2", M.String(data="hello there"))
        assert probe.collect("/text_in_llm", "String")[0].data == "hello there"
    finally:
        probe.close()
        assert system.stop() == 0


def test_map_encoding_stores_layers_in_chroma_and_survives_a_corrupt_store(tmp_path, model_server):
    db_dir = tmp_path / "chroma"
    bad_dir = tmp_path / "corrupt"
    bad_dir.mkdir()
    # (A read-only directory: see the next test.)
    (bad_dir / "chroma.sqlite3").write_bytes(b"this is not an sqlite database" * 100)
    system = SystemUnderTest(tmp_path, HEADER + f"""
detections = Topic(name="detections", msg_type="Detections")
room = Topic(name="introspection_answer", msg_type="String")
position = Topic(name="odom", msg_type="Odometry")
map_topic = Topic(name="map", msg_type="OccupancyGrid")
layer1 = MapLayer(subscribes_to=detections, temporal_change=True)
layer2 = MapLayer(subscribes_to=room, resolution_multiple=3, pre_defined=[((1.0, 1.0), "charging dock")])
mapper = MapEncoding(layers=[layer1, layer2], position=position, map_topic=map_topic,
                     config=MapConfig(map_name="map"), db_client=ChromaClient(db=ChromaDB(path={str(db_dir)!r}, embeddings="ollama",
                                                                        checkpoint="all-minilm", ollama_port={model_server.port})),
                     trigger=0.5, component_name="map_encoding")
broken = MapEncoding(layers=[MapLayer(subscribes_to=room)], position=position, map_topic=map_topic,
                     db_client=ChromaClient(db=ChromaDB(path={str(bad_dir)!r}, embeddings="ollama", checkpoint="all-minilm",
                                                        ollama_port={model_server.port})),
                     trigger=0.5, component_name="broken_map")
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[mapper, broken])
launcher.bringup()
""", duration=120).wait_up(components=["map_encoding", "broken_map"], timeout=60)
    probe = Probe(system)
    try:
        broken_pid = system.pid("broken_map")
        probe.pub("/map", _grid(0.5))
        probe.pub("/odom", _odom(2.2, 3.1))
        probe.pub("/introspection_answer", M.String(data="kitchen"))
        probe.pub("/detections", M.Detections(labels=["cup", "chair"], scores=np.ones(2), boxes=np.zeros((2, 4))))
        wait_until(lambda: probe.status("broken_map").status == M.ComponentStatus.STATUS_FAILURE_COMPONENT_LEVEL, 30,
                   what="the corrupt store reported")
        from emos.actors.agents import ChromaClient, ChromaDB

        client = ChromaClient(db=ChromaDB(path=str(db_dir), embeddings="ollama", checkpoint="all-minilm",
                                          ollama_port=model_server.port))
        client.initialize()
        wait_until(lambda: client.count("map") >= 3, 60, interval=0.5, what="three map entries stored")
        records = client.metadata_query("map")
    finally:
        probe.close()
        assert system.pid("broken_map") == broken_pid  # reported, not crashed
        assert system.stop() == 0
    docs = {r.document: r.metadata for r in records}
    assert set(docs) == {"charging dock", "kitchen", "cup, chair"}
    assert docs["kitchen"]["coordinates"][:2] == [2.25, 3.75]  # 1.5 m cells (0.5 m x 3)
    assert docs["cup, chair"]["coordinates"][:2] == [2.25, 3.25]  # 0.5 m cells
    assert docs["cup, chair"]["temporal_change"] is True
    client.deinitialize()


def test_map_encoding_on_a_read_only_store_reports_it_and_keeps_running(tmp_path, model_server):
    """Root writes through any mode, so the system runs without the capabilities that let it
    (``setpriv``): as an ordinary user on a robot whose map directory was left read-only."""
    import os
    import shutil
    import subprocess

    from emos.actors.agents import ChromaClient, ChromaDB

    if os.geteuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("needs root and setpriv to drop the capability that ignores file modes")
    store = tmp_path / "readonly_store"
    db = ChromaDB(path=str(store), embeddings="ollama", checkpoint="all-minilm", ollama_port=model_server.port)
    client = ChromaClient(db=db)
    client.initialize()
    client.add("map", ["kitchen"], embeddings=np.ones((1, 384)))
    client.deinitialize()
    subprocess.run(["chmod", "-R", "a-w", str(store)], check=True)
    try:
        system = SystemUnderTest(tmp_path, HEADER + f"""
room = Topic(name="introspection_answer", msg_type="String")
position = Topic(name="odom", msg_type="Odometry")
map_topic = Topic(name="map", msg_type="OccupancyGrid")
mapper = MapEncoding(layers=[MapLayer(subscribes_to=room)], position=position, map_topic=map_topic,
                     db_client=ChromaClient(db=ChromaDB(path={str(store)!r}, embeddings="ollama", checkpoint="all-minilm",
                                                        ollama_port={model_server.port})),
                     trigger=0.5, component_name="readonly_map")
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[mapper])
launcher.bringup()
""", duration=120, prefix=["setpriv", "--bounding-set", "-dac_override,-dac_read_search,-fowner", "--"]).wait_up(
            components=["readonly_map"], timeout=60)
        probe = Probe(system)
        try:
            wait_until(lambda: probe.status("readonly_map").status == M.ComponentStatus.STATUS_FAILURE_COMPONENT_LEVEL, 30,
                       what="the read-only store reported")
            pid = system.pid("readonly_map")
            wait_until(lambda: f"cannot open the embedded store at {str(store)!r}" in system.output(), 30, what="the store named in the log: " + system.output()[-1500:])
            assert "readonly database" in system.output()
        finally:
            probe.close()
            assert system.pid("readonly_map") == pid  # reported, not crashed
            assert system.stop() == 0
    finally:
        subprocess.run(["chmod", "-R", "u+w", str(store)], check=True)


def test_video_message_maker_cuts_on_motion(tmp_path):
    system = SystemUnderTest(tmp_path, HEADER + """
image = Topic(name="image_raw", msg_type="Image")
video = Topic(name="video", msg_type="Video")
maker = VideoMessageMaker(inputs=[image], outputs=[video], component_name="video_maker",
                          config=VideoMessageMakerConfig(min_video_frames=3, max_video_frames=50,
                                                         motion_estimation_func="frame_difference", threshold=0.05))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[maker])
launcher.bringup()
""", duration=60).wait_up(components=["video_maker"], timeout=60)
    probe = Probe(system)
    try:
        probe.sub("/video", "Video")
        still = np.zeros((48, 64, 3), np.uint8)
        import time
        for i in range(12):  # 2 still frames, 6 moving frames, 4 still frames
            frame = still.copy()
            if 2 <= i < 8:
                frame[:, (i * 7) % 64:] = 255 if i % 2 else 80
            probe.pub("/image_raw", M.Image.from_numpy(frame))
            time.sleep(0.03)
        (vid,) = probe.collect("/video", "Video")
        assert 3 <= len(vid.frames) <= 7
        assert probe.drain("/video", "Video") == []
    finally:
        probe.close()
        assert system.stop() == 0
