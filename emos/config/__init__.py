"""Component configuration: attrs configs, validators, QoS, run types and config files."""
from emos.config import qos
from emos.config import validators as base_validators
from emos.config.base import BaseAttrs, BaseComponentConfig, ComponentRunType
from emos.config.loader import ConfigError, load_into, read_config_file
from emos.config.qos import (
    BEST_EFFORT,
    KEEP_ALL,
    KEEP_LAST,
    RELIABLE,
    TRANSIENT_LOCAL,
    VOLATILE,
    DurabilityPolicy,
    HistoryPolicy,
    QoSConfig,
    ReliabilityPolicy,
)

__all__ = [
    "base_validators", "BaseAttrs", "BaseComponentConfig", "ComponentRunType", "ConfigError", "load_into",
    "read_config_file", "QoSConfig", "HistoryPolicy", "ReliabilityPolicy", "DurabilityPolicy", "KEEP_LAST",
    "KEEP_ALL", "RELIABLE", "BEST_EFFORT", "VOLATILE", "TRANSIENT_LOCAL", "qos",
]
