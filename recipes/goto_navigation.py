"""Go-to-X (foundation recipe): "go to the kitchen" becomes a PoseStamped goal, read from the
semantic map (RAG) by an LLM. A navigation planner subscribed to ``goal_point`` drives there.

    emos serve models --script recipes/models/responder.yaml &
    emos run recipes/goto_navigation.py

The ``map`` collection is the one recipes/semantic_map.py fills.
"""
import json
import os

import numpy as np

from emos import Launcher, Topic
from emos.actors.agents import LLM, ChromaClient, ChromaDB, LLMConfig, OllamaClient, OllamaModel

MODELS_PORT = int(os.environ.get("EMOS_MODELS_PORT", "8000"))

llama = OllamaModel(name="llama", checkpoint="llama3.2:3b")
llama_client = OllamaClient(llama, port=MODELS_PORT)

# Embeddings from the model server's all-MiniLM-L6-v2 (as from an Ollama server).
chroma = ChromaDB(embeddings="ollama", checkpoint="all-minilm", ollama_port=MODELS_PORT)
chroma_client = ChromaClient(db=chroma)

goto_in = Topic(name="goto_in", msg_type="String")
goal_point = Topic(name="goal_point", msg_type="PoseStamped")

config = LLMConfig(enable_rag=True, collection_name="map", distance_func="l2", n_results=1, add_metadata=True)

goto = LLM(
    inputs=[goto_in],
    outputs=[goal_point],
    model_client=llama_client,
    db_client=chroma_client,
    trigger=goto_in,
    config=config,
    component_name="go_to_x",
)

goto.set_component_prompt(
    template="""From the given metadata, extract coordinates and provide
the coordinates in the following json format:\n {"position": coordinates}"""
)


def llm_answer_to_goal_point(output: str) -> np.ndarray | None:
    # extract the json part of the output string (including brackets)
    json_string = output[output.find("{") : output.rfind("}") + 1]
    # if there is an error, return None, i.e. no output would be published to goal_point
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

launcher = Launcher()
launcher.add_pkg(components=[goto])
launcher.bringup()
