"""VLM planning-task outputs parsed from model text into typed results."""
from __future__ import annotations

import numpy as np
import pytest

from emos.actors.agents.logic.vlm_tasks import (
    AffordanceResult,
    GeneralResult,
    GroundingResult,
    PointingResult,
    TrajectoryResult,
    VLMParseError,
    parse_vlm_output,
)

pytestmark = pytest.mark.unit


def test_general_is_the_stripped_text():
    assert parse_vlm_output("general", "  A kitchen.\n") == GeneralResult("A kitchen.")


@pytest.mark.parametrize("text,expected", [
    ("The cup is at (120, 45) and the plate at (30.5, 60).", [[120, 45], [30.5, 60]]),
    ('```json\n[{"point_2d": [200, 310], "label": "handle"}]\n```', [[200, 310]]),
    ('{"point_2d": [7, 8]}', [[7, 8]]),
    ("[[1, 2], [3, 4]]", [[1, 2], [3, 4]]),
])
def test_pointing(text, expected):
    result = parse_vlm_output("pointing", text)
    assert isinstance(result, PointingResult)
    assert np.allclose(result.points, expected) and result.points.shape == (len(expected), 2)


def test_trajectory_keeps_order_and_needs_two_points():
    result = parse_vlm_output("trajectory", "Move along [(10, 20), (30, 40), (50, 60)] to the sink.")
    assert isinstance(result, TrajectoryResult)
    assert result.points.tolist() == [[10, 20], [30, 40], [50, 60]]
    with pytest.raises(VLMParseError, match="at least 2 point"):
        parse_vlm_output("trajectory", "Go to (10, 20).")


def test_affordance_and_grounding_boxes():
    affordance = parse_vlm_output("affordance", "Grasp the mug here: [100, 200, 150, 260].")
    assert isinstance(affordance, AffordanceResult) and affordance.boxes.tolist() == [[100, 200, 150, 260]]
    grounding = parse_vlm_output("grounding", 'Found: [{"bbox_2d": [1, 2, 30, 40], "label": "cup"}, '
                                              '{"bbox_2d": [5, 5, 9, 9], "label": "plate"}]')
    assert isinstance(grounding, GroundingResult)
    assert grounding.boxes.shape == (2, 4) and grounding.labels == ["cup", "plate"]
    plain = parse_vlm_output("grounding", "[12, 14, 60, 80]")
    assert plain.boxes.tolist() == [[12, 14, 60, 80]] and plain.labels == [None]


def test_clear_errors():
    with pytest.raises(VLMParseError, match=r"grounding output: expected at least one box.*'I cannot see it'"):
        parse_vlm_output("grounding", "I cannot see it")
    with pytest.raises(VLMParseError, match="x2 >= x1"):
        parse_vlm_output("affordance", "[50, 20, 10, 30]")
    with pytest.raises(VLMParseError, match="pointing output"):
        parse_vlm_output("pointing", "nothing to point at")
    with pytest.raises(ValueError, match="task 'dance'"):
        parse_vlm_output("dance", "x")
    with pytest.raises(TypeError, match="model text"):
        parse_vlm_output("pointing", None)
