"""Semantic routing in LLM mode (foundation recipe "semantic routing", Option 2: LLM Mode):
the page's recipe with the router the page gives for LLM mode, which asks the Llama model to
pick the route (one tool per route) instead of measuring distances in a vector DB.

    emos serve models --script recipes/models/responder.yaml &
    emos run recipes/semantic_routing_llm.py
    emos topic pub /question String '{"data": "Please go to the kitchen"}'   # -> /goal_point
    emos topic pub /question String '{"data": "What is the capital of Spain?"}'  # -> /text_out_llm

The same code as recipes/semantic_routing.py (the page's complete code, ported: imports, the
model server's port, errata) but for the router: the page's Option 2 block, as it is. Offline,
the routing decision comes from the scripted responder (recipes/models/responder.yaml: a
movement request calls the go-to route's tool; anything else calls none, and the router falls
back to its default, the first route), standing in for llama3.2.
"""
import json
import os

import numpy as np

from emos import Launcher, Topic
from emos.actors.agents import (
    LLM,
    ChromaClient,
    ChromaDB,
    LLMConfig,
    OllamaClient,
    OllamaModel,
    Route,
    SemanticRouter,
    SemanticRouterConfig,  # noqa: F401 - the page imports it; LLM mode needs none
)

MODELS_PORT = int(os.environ.get("EMOS_MODELS_PORT", "8000"))

llama = OllamaModel(name="llama", checkpoint="llama3.2:3b")
llama_client = OllamaClient(llama, port=MODELS_PORT)

chroma = ChromaDB(embeddings="ollama", checkpoint="all-minilm", ollama_port=MODELS_PORT)
chroma_client = ChromaClient(db=chroma)

llm_in = Topic(name="text_in_llm", msg_type="String")
llm_out = Topic(name="text_out_llm", msg_type="String")

llm = LLM(
    inputs=[llm_in],
    outputs=[llm_out],
    model_client=llama_client,
    trigger=llm_in,
    component_name="generic_llm",
)

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

goto.set_component_prompt(
    template="""From the given metadata, extract coordinates and provide
the coordinates in the following json format:\n {"position": coordinates}"""
)


def llm_answer_to_goal_point(output: str) -> np.ndarray | None:
    # errata: rfind (the last '}'), and a position that is a list or a "x, y, z" string
    json_string = output[output.find("{") : output.rfind("}") + 1]
    try:
        json_dict = json.loads(json_string)
        position = json_dict["position"]
        if isinstance(position, list):
            return np.array(position, dtype=np.float64).ravel()
        return np.fromstring(position, sep=",", dtype=np.float64)
    except Exception:
        return


goto.add_publisher_preprocessor(goal_point, llm_answer_to_goal_point)

query_topic = Topic(name="question", msg_type="String")

goto_route = Route(
    routes_to=goto_in,
    samples=["Go to the door", "Go to the kitchen", "Get me a glass", "Fetch a ball", "Go to hallway"],
)

llm_route = Route(
    routes_to=llm_in,
    samples=["What is the capital of France?", "Is there life on Mars?", "How many tablespoons in a cup?",
             "How are you today?", "Whats up?"],
)

# No SemanticRouterConfig needed, we can use LLMConfig or let it be default
router = SemanticRouter(
    inputs=[query_topic],
    routes=[llm_route, goto_route],
    model_client=llama_client,  # Providing model_client enables LLM Mode
    component_name="smart_router"
)

launcher = Launcher()
launcher.add_pkg(components=[llm, goto, router])
launcher.bringup()
