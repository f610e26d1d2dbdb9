"""Configs: attrs validators on set, YAML/TOML/JSON files with a common section, clear errors."""
import json

import pytest
from attrs import define, field

from emos import BaseComponent, Topic
from emos.config import BaseComponentConfig, ConfigError, QoSConfig, base_validators
from emos.config.qos import DurabilityPolicy

pytestmark = pytest.mark.unit


@define(kw_only=True)
class AwesomeConfig(BaseComponentConfig):
    extra_float: float = field(default=10.0, validator=base_validators.in_range(min_value=1e-9, max_value=1e9))
    extra_flag: bool = field(default=True)
    mode: str = field(default="fast", validator=base_validators.in_(["fast", "safe"]))


class Awesome(BaseComponent):
    def __init__(self, **kwargs):
        self.config = kwargs.pop("config", None) or AwesomeConfig()
        super().__init__(config=self.config, **kwargs)


FILES = {
    "yaml": """
/**:
  loop_rate: 5.0
  unknown_common_key: 1
awesome:
  extra_float: 2.5
  extra_flag: false
  inputs:
    cam:
      name: /camera/rgb
      msg_type: Image
""",
    "toml": """
["/**"]
loop_rate = 5.0
unknown_common_key = 1

[awesome]
extra_float = 2.5
extra_flag = false

[awesome.inputs.cam]
name = "/camera/rgb"
msg_type = "Image"
""",
    "json": json.dumps({"/**": {"loop_rate": 5.0, "unknown_common_key": 1}, "awesome": {"extra_float": 2.5, "extra_flag": False, "inputs": {"cam": {"name": "/camera/rgb", "msg_type": "Image"}}}}),
}


@pytest.mark.parametrize("fmt", sorted(FILES))
def test_config_files_in_every_format_apply_common_then_own_section(tmp_path, fmt):
    path = tmp_path / f"params.{fmt}"
    path.write_text(FILES[fmt])
    comp = Awesome(component_name="awesome", config_file=str(path))
    assert comp.config.loop_rate == 5.0  # from /**
    assert comp.config.extra_float == 2.5 and comp.config.extra_flag is False  # own section
    assert [t.name for t in comp.in_topics] == ["/camera/rgb"]
    other = Awesome(component_name="other", config_file=str(path))
    assert other.config.extra_float == 10.0 and other.config.loop_rate == 5.0


def test_validators_run_on_set_and_name_the_parameter():
    cfg = AwesomeConfig()
    with pytest.raises(ValueError, match=r"AwesomeConfig\.extra_float must be in"):
        cfg.extra_float = -1.0
    with pytest.raises(ValueError, match="must be one of"):
        cfg.mode = "reckless"
    assert cfg.extra_float == 10.0


def test_bad_values_in_files_name_file_key_and_expected_type(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("awesome:\n  extra_float: fast\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml: awesome\.extra_float: expected float, got str 'fast'"):
        Awesome(component_name="awesome", config_file=str(path))
    path.write_text("awesome:\n  extra_floot: 1.0\n")
    with pytest.raises(ConfigError, match=r"unknown parameter 'awesome\.extra_floot'.*extra_float"):
        Awesome(component_name="awesome", config_file=str(path))
    path.write_text("awesome:\n  extra_float: 1e12\n")
    with pytest.raises(ConfigError, match="extra_float"):
        Awesome(component_name="awesome", config_file=str(path))


def test_malformed_and_missing_files(tmp_path):
    bad = tmp_path / "broken.toml"
    bad.write_text("[awesome\nx = 1")
    with pytest.raises(ConfigError, match="broken.toml is not valid TOML"):
        Awesome(component_name="awesome", config_file=str(bad))
    with pytest.raises(ConfigError, match="does not exist"):
        Awesome(component_name="awesome", config_file=str(tmp_path / "nope.yaml"))
    odd = tmp_path / "params.ini"
    odd.write_text("x=1")
    with pytest.raises(ConfigError, match="unknown format"):
        Awesome(component_name="awesome", config_file=str(odd))


def test_config_update_is_all_or_nothing():
    cfg = AwesomeConfig()
    with pytest.raises(ValueError):
        cfg.update(extra_float=3.0, mode="reckless")
    assert cfg.extra_float == 10.0
    cfg.update(extra_float=3.0, mode="safe")
    assert (cfg.extra_float, cfg.mode) == (3.0, "safe")
    with pytest.raises(AttributeError, match="has no parameter speed"):
        cfg.update(speed=1)


def test_topic_definition_errors_happen_at_definition():
    with pytest.raises(ValueError, match="invalid"):
        Topic(name="bad//name", msg_type="String")
    with pytest.raises(Exception, match="did you mean"):
        Topic(name="ok", msg_type="Strin")
    t = Topic(name="map", msg_type="OccupancyGrid", qos_profile=QoSConfig(durability="TRANSIENT_LOCAL", queue_size=1))
    assert t.name == "/map" and t.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
    with pytest.raises(ValueError, match="queue_size"):
        QoSConfig(queue_size=0)


def test_component_argument_errors():
    with pytest.raises(ValueError, match="component_name"):
        BaseComponent(component_name="1abc")
    with pytest.raises(TypeError, match="inputs must be Topic objects"):
        BaseComponent(component_name="c", inputs=["scan"])
    with pytest.raises(ValueError, match="has no main_srv_type"):
        BaseComponent(component_name="c", run_type="Server")
    with pytest.raises(ValueError, match="run_type must be one of"):
        BaseComponent(component_name="c", run_type="Sometimes")
    c = BaseComponent(component_name="c", trigger=0.5)
    assert c.run_type.value == "Timed" and c.config.loop_rate == 2.0


def test_launcher_config_file_configures_every_component_it_is_given(tmp_path):
    from emos import Launcher

    path = tmp_path / "robot.toml"
    path.write_text('["/**"]\nloop_rate = 7.0\n\n[awesome]\nextra_float = 3.5\n')
    launcher = Launcher(config_file=str(path), multi_processing=True)
    a, b = Awesome(component_name="awesome"), Awesome(component_name="other")
    launcher.add_pkg(components=[a, b])
    assert (a.config.loop_rate, a.config.extra_float) == (7.0, 3.5)
    assert (b.config.loop_rate, b.config.extra_float) == (7.0, 10.0)
    with pytest.raises(ValueError, match="already added: awesome"):
        launcher.add_pkg(components=[Awesome(component_name="awesome")])
    with pytest.raises(TypeError, match="BaseComponent instances"):
        launcher.add_pkg(components=["not a component"])
    with pytest.raises(ValueError, match="stop_timeout must be a positive number"):
        Launcher(stop_timeout=-1)
