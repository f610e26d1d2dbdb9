"""Semantic map (foundation recipe): detections and a VLM's periodic answer stored in a vector
DB at the robot's position.

    emos serve models --script recipes/models/responder.yaml --resp-port 6379 &
    emos run recipes/semantic_map.py

Needs ``odom`` (Odometry) and ``map`` (OccupancyGrid) from the robot (or the simulator).
"""
import os

from emos import FixedInput, Launcher, Topic
from emos.actors.agents import (
    MLLM,
    ChromaClient,
    ChromaDB,
    MapConfig,
    MapEncoding,
    MapLayer,
    OllamaClient,
    OllamaModel,
    RoboMLRESPClient,
    Vision,
    VisionConfig,
    VisionModel,
)

MODELS_PORT = int(os.environ.get("EMOS_MODELS_PORT", "8000"))
MODELS_RESP_PORT = int(os.environ.get("EMOS_MODELS_RESP_PORT", "6379"))

image0 = Topic(name="image_raw", msg_type="Image")
detections_topic = Topic(name="detections", msg_type="Detections")

object_detection = VisionModel(name="object_detection", checkpoint="dino-4scale_r50_8xb2-12e_coco")
roboml_detection = RoboMLRESPClient(object_detection, port=MODELS_RESP_PORT)

detection_config = VisionConfig(threshold=0.5)
vision = Vision(
    inputs=[image0],
    outputs=[detections_topic],
    trigger=image0,
    config=detection_config,
    model_client=roboml_detection,
    component_name="detection_component",
)

qwen_vl = OllamaModel(name="qwen_vl", checkpoint="qwen2.5vl:latest")
qwen_client = OllamaClient(qwen_vl, port=MODELS_PORT)

introspection_query = FixedInput(
    name="introspection_query",
    msg_type="String",
    fixed="What kind of a room is this? Is it an office, a bedroom or a kitchen? Give a one word answer, out of the given choices",
)
introspection_answer = Topic(name="introspection_answer", msg_type="String")

# This component answers the same question every 15 seconds
introspector = MLLM(
    inputs=[introspection_query, image0],
    outputs=[introspection_answer],
    model_client=qwen_client,
    trigger=15.0,
    component_name="introspector",
)


def introspection_validation(output: str) -> str | None:
    for option in ["office", "bedroom", "kitchen"]:
        if option in output.lower():
            return option


introspector.add_publisher_preprocessor(introspection_answer, introspection_validation)

layer1 = MapLayer(subscribes_to=detections_topic, temporal_change=True)
layer2 = MapLayer(subscribes_to=introspection_answer, resolution_multiple=3)

position = Topic(name="odom", msg_type="Odometry")
map_topic = Topic(name="map", msg_type="OccupancyGrid")

# Embeddings from the model server's all-MiniLM-L6-v2 (as from an Ollama server).
chroma = ChromaDB(embeddings="ollama", checkpoint="all-minilm", ollama_port=MODELS_PORT)
chroma_client = ChromaClient(db=chroma)

map_conf = MapConfig(map_name="map")
map = MapEncoding(
    layers=[layer1, layer2],
    position=position,
    map_topic=map_topic,
    config=map_conf,
    db_client=chroma_client,
    trigger=15.0,
    component_name="map_encoding",
)

launcher = Launcher()
launcher.add_pkg(components=[vision, introspector, map])
launcher.bringup()
