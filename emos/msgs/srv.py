"""Request and response types of common services (std_srvs)."""
from __future__ import annotations

from emos.msgs import fields as F
from emos.msgs.registry import Message, message_type


@message_type("std_srvs", name="Trigger_Request")
class TriggerRequest(Message):
    pass


@message_type("std_srvs", name="Trigger_Response")
class TriggerResponse(Message):
    success: bool = F.boolean()
    message: str = F.string()


@message_type("std_srvs", name="SetBool_Request")
class SetBoolRequest(Message):
    data: bool = F.boolean()


@message_type("std_srvs", name="SetBool_Response")
class SetBoolResponse(Message):
    success: bool = F.boolean()
    message: str = F.string()
