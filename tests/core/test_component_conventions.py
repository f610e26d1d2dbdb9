"""The two component conventions (keyed topics, listed topics) share one rule for what a role
accepts and one rule for the config class (emos.core.conventions)."""
from __future__ import annotations

from typing import ClassVar

import pytest

from emos import BaseComponent, BaseComponentConfig, Topic
from emos.core import conventions, keyed
from emos.core.conventions import AllowedTopic, check_topics, resolve_config, role_spec
from emos.core.keyed import KeyedComponent

pytestmark = pytest.mark.unit

ODOM = Topic(name="odom", msg_type="Odometry")
SCAN = Topic(name="scan", msg_type="LaserScan")


class Follower(KeyedComponent):
    allowed_inputs: ClassVar[dict[str, AllowedTopic]] = {"location": AllowedTopic(types=("Odometry", "PoseStamped"), default=ODOM)}
    allowed_outputs: ClassVar[dict[str, AllowedTopic]] = {"command": AllowedTopic(types=("Twist",), default=Topic(name="/cmd_vel", msg_type="Twist"), required=True)}


def test_one_declaration_type_for_both_conventions():
    assert keyed.AllowedTopic is conventions.AllowedTopic
    spec = role_spec(("String", "Odometry"))  # a listed role: the types, any number of topics
    assert spec is not None and spec.number == -1 and not spec.required
    assert role_spec(()) is None  # no declared types: the role takes any message type


def test_the_same_rule_checks_a_keyed_role_and_a_listed_role():
    spec = AllowedTopic(types=("Odometry",), number=1, required=True)
    assert check_topics("c", "Kind", "input", ODOM, spec, key="location") == [ODOM]
    # keyed: the error names the key; listed: it names the topic
    with pytest.raises(TypeError, match=r"component 'c' \(Kind\): input 'location' accepts Odometry, but topic '/scan' is LaserScan"):
        check_topics("c", "Kind", "input", [SCAN], spec, key="location")
    with pytest.raises(TypeError, match=r"input '/scan' carries sensor_msgs/msg/LaserScan, but this component takes inputs of type Odometry"):
        check_topics("c", "Kind", "input", [SCAN], spec)
    with pytest.raises(ValueError, match="input 'location' takes at most 1 topic"):
        check_topics("c", "Kind", "input", [ODOM, ODOM], spec, key="location")
    with pytest.raises(ValueError, match="input 'location' is required"):
        check_topics("c", "Kind", "input", None, spec, key="location")
    with pytest.raises(TypeError, match="inputs must be Topic objects, got str"):
        check_topics("c", "Kind", "input", ["odom"], None)


def test_both_conventions_and_the_plain_base_use_the_rule():
    with pytest.raises(TypeError, match=r"\(Follower\): input 'location' accepts Odometry or PoseStamped, but topic '/scan' is LaserScan"):
        Follower(component_name="f", inputs={"location": SCAN})
    from emos.actors.agents import LLM, OllamaClient, OllamaModel

    client = OllamaClient(OllamaModel(name="llama", checkpoint="llama3.2:3b"))
    q = Topic(name="q", msg_type="String")
    with pytest.raises(TypeError, match=r"\(LLM\): input '/scan' carries sensor_msgs/msg/LaserScan, but this component takes inputs of type String"):
        LLM(inputs=[SCAN], outputs=[q], model_client=client, trigger=q, component_name="llm")
    with pytest.raises(TypeError, match="outputs must be Topic objects"):
        LLM(inputs=[q], outputs=["a"], model_client=client, trigger=q, component_name="llm")
    with pytest.raises(TypeError, match="inputs must be Topic objects"):
        BaseComponent(component_name="plain", inputs=["odom"])


class OwnConfig(BaseComponentConfig):
    pass


class Plain(BaseComponent):
    @classmethod
    def config_class(cls) -> type[BaseComponentConfig]:
        return OwnConfig


def test_every_convention_gets_its_config_class_from_one_rule():
    assert resolve_config("c", "Kind", None, OwnConfig).__class__ is OwnConfig
    with pytest.raises(TypeError, match=r"component 'c' \(Kind\): config must be a OwnConfig, got BaseComponentConfig"):
        resolve_config("c", "Kind", BaseComponentConfig(), OwnConfig)
    # the plain base, a keyed component and a listed (agents) component: a default of their class...
    assert type(BaseComponent(component_name="b").config) is BaseComponentConfig
    assert type(Plain(component_name="p").config) is OwnConfig
    from emos.actors.agents import LLM, LLMConfig, OllamaClient, OllamaModel
    from emos.actors.nav.components import Planner, PlannerConfig

    assert type(Planner(component_name="planner").config) is PlannerConfig
    client = OllamaClient(OllamaModel(name="llama", checkpoint="llama3.2:3b"))
    q = Topic(name="q", msg_type="String")
    assert type(LLM(inputs=[q], outputs=[q], model_client=client, trigger=q, component_name="llm").config) is LLMConfig
    assert LLM.config_class() is LLMConfig and Planner.config_class() is PlannerConfig
    # ...and one of another class fails naming the class it needs
    with pytest.raises(TypeError, match=r"\(Plain\): config must be a OwnConfig"):
        Plain(component_name="p", config=BaseComponentConfig())
    with pytest.raises(TypeError, match=r"\(LLM\): config must be a LLMConfig, got BaseComponentConfig"):
        LLM(inputs=[q], outputs=[q], model_client=client, config=BaseComponentConfig(), trigger=q, component_name="llm")
    with pytest.raises(TypeError, match=r"config must be a PlannerConfig"):
        Planner(component_name="planner", config=BaseComponentConfig())
