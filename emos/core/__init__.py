"""Components, their lifecycle and health, and the services and actions they serve."""
from emos.config.base import BaseComponentConfig, ComponentRunType
from emos.core.component import BaseComponent, ComponentError
from emos.core.component_fallbacks import ComponentFallbacks
from emos.core.health import HealthLevel, Status
from emos.core.lifecycle import InvalidTransition, LifecycleState, Transition
from emos.core.service_config import ServiceClientConfig
from emos.core.services import ActionCanceled, ActionClient, GoalHandle, ServiceClient

__all__ = [
    "BaseComponent", "BaseComponentConfig", "ComponentRunType", "ComponentError", "HealthLevel", "Status",
    "LifecycleState", "Transition", "InvalidTransition", "ServiceClient", "ActionClient", "ActionCanceled", "GoalHandle",
    "ComponentFallbacks", "ServiceClientConfig",
]
