"""Complete agent (foundation capstone): speech in and out, vision, visual Q&A, a semantic map,
a general LLM, Go-to-X over the map, and a router that picks the right one for each question.

    emos serve models --script recipes/models/responder.yaml &
    emos run recipes/complete_agent.py

multiprocessing_agent.py runs this same agent with every component in its own process.

Inputs: ``audio0`` (or ``question`` as text), ``image_raw``, ``odom``, ``map``.
Outputs: ``answer`` (text, and speech on the speakers when there are any), ``goal_point``.
"""
import json
import os

import numpy as np

from emos import FixedInput, Launcher, Topic
from emos.actors.agents import (
    LLM,
    MLLM,
    ChromaClient,
    ChromaDB,
    LLMConfig,
    MapConfig,
    MapEncoding,
    MapLayer,
    OllamaClient,
    OllamaModel,
    RoboMLHTTPClient,
    Route,
    SemanticRouter,
    SemanticRouterConfig,
    SpeechT5,
    SpeechToText,
    TextToSpeech,
    TextToSpeechConfig,
    Vision,
    VisionConfig,
    Whisper,
)

MODELS_PORT = int(os.environ.get("EMOS_MODELS_PORT", "8000"))

### Setup our models and vectordb ###
whisper = Whisper(name="whisper")
whisper_client = RoboMLHTTPClient(whisper, port=MODELS_PORT)
speecht5 = SpeechT5(name="speecht5")
speecht5_client = RoboMLHTTPClient(speecht5, port=MODELS_PORT)
qwen_vl = OllamaModel(name="qwen_vl", checkpoint="qwen2.5vl:latest")
qwen_client = OllamaClient(qwen_vl, port=MODELS_PORT)
llama = OllamaModel(name="llama", checkpoint="llama3.2:3b")
llama_client = OllamaClient(llama, port=MODELS_PORT)
chroma = ChromaDB(embeddings="ollama", checkpoint="all-minilm", ollama_port=MODELS_PORT)
chroma_client = ChromaClient(db=chroma)

### Setup our components ###
audio_in = Topic(name="audio0", msg_type="Audio")
query_topic = Topic(name="question", msg_type="String")
speech_to_text = SpeechToText(
    inputs=[audio_in],
    outputs=[query_topic],
    model_client=whisper_client,
    trigger=audio_in,
    component_name="speech_to_text",
)

query_answer = Topic(name="answer", msg_type="String")
t2s_config = TextToSpeechConfig(play_on_device=True)
text_to_speech = TextToSpeech(
    inputs=[query_answer],
    trigger=query_answer,
    model_client=speecht5_client,
    config=t2s_config,
    component_name="text_to_speech",
)

image0 = Topic(name="image_raw", msg_type="Image")
detections_topic = Topic(name="detections", msg_type="Detections")
detection_config = VisionConfig(threshold=0.5, enable_local_classifier=True)
vision = Vision(
    inputs=[image0],
    outputs=[detections_topic],
    trigger=image0,
    config=detection_config,
    component_name="object_detection",
)

mllm_query = Topic(name="mllm_query", msg_type="String")
mllm = MLLM(
    inputs=[mllm_query, image0, detections_topic],
    outputs=[query_answer],
    model_client=qwen_client,
    trigger=mllm_query,
    component_name="visual_q_and_a",
)
# errata: the query topic is mllm_query; the spec's {{ text0 }} does not exist in this graph
mllm.set_component_prompt(
    template="""Imagine you are a robot.
This image has following items: {{ detections }}.
Answer the following about this image: {{ mllm_query }}"""
)

introspection_query = FixedInput(
    name="introspection_query",
    msg_type="String",
    fixed="What kind of a room is this? Is it an office, a bedroom or a kitchen? Give a one word answer, out of the given choices",
)
introspection_answer = Topic(name="introspection_answer", msg_type="String")
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
map_conf = MapConfig(map_name="map")
map = MapEncoding(
    layers=[layer1, layer2],
    position=position,
    map_topic=map_topic,
    config=map_conf,
    db_client=chroma_client,
    trigger=15.0,
    component_name="map_encoder",
)

llm_query = Topic(name="llm_query", msg_type="String")
llm = LLM(
    inputs=[llm_query],
    outputs=[query_answer],
    model_client=llama_client,
    trigger=[llm_query],
    component_name="general_q_and_a",
)

goto_query = Topic(name="goto_query", msg_type="String")
goal_point = Topic(name="goal_point", msg_type="PoseStamped")
goto_config = LLMConfig(
    enable_rag=True,
    collection_name="map",
    distance_func="l2",
    n_results=1,
    add_metadata=True,
)
goto = LLM(
    inputs=[goto_query],
    outputs=[goal_point],
    model_client=llama_client,
    config=goto_config,
    db_client=chroma_client,
    trigger=goto_query,
    component_name="go_to_x",
)
goto.set_component_prompt(
    template="""From the given metadata, extract coordinates and provide
the coordinates in the following json format:\n {"position": coordinates}"""
)


def llm_answer_to_goal_point(output: str) -> np.ndarray | None:
    json_string = output[output.find("{") : output.rfind("}") + 1]
    try:
        json_dict = json.loads(json_string)
        # errata: the map metadata holds a list; np.fromstring only reads "x, y, z" strings
        position = json_dict["position"]
        if isinstance(position, list):
            coordinates = np.array(position, dtype=np.float64).ravel()
        else:
            coordinates = np.fromstring(position, sep=",", dtype=np.float64)
        print("Coordinates Extracted:", coordinates)
        if coordinates.shape[0] < 2 or coordinates.shape[0] > 3:
            return
        elif coordinates.shape[0] == 2:  # sometimes LLMs avoid adding the zeros of z-dimension
            coordinates = np.append(coordinates, 0)
        return coordinates
    except Exception:
        return


goto.add_publisher_preprocessor(goal_point, llm_answer_to_goal_point)

goto_route = Route(
    routes_to=goto_query,
    samples=["Go to the door", "Go to the kitchen", "Get me a glass", "Fetch a ball", "Go to hallway"],
)
llm_route = Route(
    routes_to=llm_query,
    samples=["What is the capital of France?", "Is there life on Mars?", "How many tablespoons in a cup?",
             "How are you today?", "Whats up?"],
)
mllm_route = Route(
    routes_to=mllm_query,
    samples=["Are we indoors or outdoors", "What do you see?", "Whats in front of you?", "Where are we",
             "Do you see any people?", "How many things are infront of you?", "Is this room occupied?"],
)
router_config = SemanticRouterConfig(router_name="go-to-router", distance_func="l2")
router = SemanticRouter(
    inputs=[query_topic],
    routes=[llm_route, goto_route, mllm_route],
    default_route=llm_route,
    config=router_config,
    db_client=chroma_client,
    component_name="router",
)

components = [mllm, llm, goto, introspector, map, router, speech_to_text, text_to_speech, vision]

# Run as a script (emos run, python3), the recipe brings the agent up; imported (as
# multiprocessing_agent.py does), it only builds the graph.
if __name__ == "__main__":
    launcher = Launcher()
    launcher.add_pkg(components=components)
    launcher.bringup()
