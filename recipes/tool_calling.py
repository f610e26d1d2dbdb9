"""Go-to-X with tool calling (foundation recipe): the LLM reads the semantic map (RAG) and calls
a tool with the coordinates; the tool's value is published as a PoseStamped goal.

    emos serve models --script recipes/models/responder.yaml &
    emos run recipes/tool_calling.py

The ``map`` collection is the one recipes/semantic_map.py fills.
"""
import os

import numpy as np

from emos import Launcher, Topic
from emos.actors.agents import LLM, ChromaClient, ChromaDB, LLMConfig, OllamaClient, OllamaModel

MODELS_PORT = int(os.environ.get("EMOS_MODELS_PORT", "8000"))

llama = OllamaModel(name="llama", checkpoint="llama3.2:3b")
llama_client = OllamaClient(llama, port=MODELS_PORT)

chroma = ChromaDB(embeddings="ollama", checkpoint="all-minilm", ollama_port=MODELS_PORT)
chroma_client = ChromaClient(db=chroma)

goto_in = Topic(name="goto_in", msg_type="String")
goal_point = Topic(name="goal_point", msg_type="PoseStamped")

config = LLMConfig(
    enable_rag=True,
    collection_name="map",
    distance_func="l2",
    n_results=1,
    add_metadata=True,
)

goto = LLM(
    inputs=[goto_in],
    outputs=[goal_point],
    model_client=llama_client,
    db_client=chroma_client,
    trigger=goto_in,
    config=config,
    component_name="go_to_x",
)

goto.set_component_prompt(template="""What are the position coordinates in the given metadata?""")


def get_coordinates(position: list[float]) -> np.ndarray:
    """Get position coordinates"""
    return np.array(position, dtype=float)


# As in the spec (see errata): "list[float]" becomes a JSON-schema array of numbers, and the
# "required" list beside "parameters" is honoured.
function_description = {
    "type": "function",
    "function": {
        "name": "get_coordinates",
        "description": "Get position coordinates",
        "parameters": {
            "type": "object",
            "properties": {
                "position": {
                    "type": "list[float]",
                    "description": "The position coordinates in x, y and z",
                }
            },
        },
        "required": ["position"],
    },
}

goto.register_tool(
    tool=get_coordinates,
    tool_description=function_description,
    send_tool_response_to_model=False,
)

launcher = Launcher()
launcher.add_pkg(components=[goto])
launcher.bringup()
