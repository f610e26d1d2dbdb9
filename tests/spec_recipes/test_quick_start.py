"""The spec's first recipes (getting-started/quickstart.md and the custom recipe of
getting-started/cli.md), ported under recipes/, run with ``emos run`` against the real model
server (recipes/models/responder.yaml stands in for qwen2.5vl): a question on /text0 with a
camera image on /image_raw gets an answer on /text1, through the page's prompt template."""
from __future__ import annotations

import numpy as np
import pytest

from emos import msgs as M
from tests.agents.components_helpers import Probe
from tests.agents.fixtures.server_process import start_server
from tests.runtime.helpers import REPO, SystemUnderTest

pytestmark = pytest.mark.process

RECIPES = REPO / "recipes"


@pytest.fixture(scope="module")
def server():
    server = start_server(script=str(RECIPES / "models" / "responder.yaml"))
    yield server
    server.stop()


# recipe, component, the answer the stand-in model gives to what the recipe's prompt sends it
@pytest.mark.parametrize("recipe,component,answer", [
    # the page's template puts the question into "Answer the following about this image: ..."
    ("quick_start.py", "vqa", "Looking at the image: What do you see?"),
    # no template on the cli page: the question goes to the model as it is
    ("cli_custom_recipe.py", "vlm", "You said: What do you see?"),
])
def test_the_vlm_answers_a_question_about_the_camera_image(tmp_path, server, recipe, component, answer):
    env = {"EMOS_MODELS_PORT": str(server.port), "HOME": str(tmp_path)}
    system = SystemUnderTest(tmp_path, (RECIPES / recipe).read_text(), duration=120, env=env)
    probe = None
    try:
        system.wait_up(components=[component], timeout=90)
        probe = Probe(system)
        probe.sub("/text1", "String")
        probe.pub("/image_raw", M.Image.from_numpy(np.full((120, 160, 3), 128, np.uint8)))
        probe.pub("/text0", M.String(data="What do you see?"))
        assert probe.collect("/text1", "String", timeout=60)[0].data == answer
    finally:
        if probe is not None:
            probe.close()
        assert system.stop() == 0, system.output()[-3000:]
