"""Events, conditions and actions: what the runtime reacts to, and how."""
from emos.events.action import Action, ActionError
from emos.events.conditions import Condition, ConditionError, MsgPath
from emos.events.event import Blackboard, Event, EventTracker
from emos.events.named import OnAny, OnContainsAll, OnContainsAny, OnDifferent, OnEqual, OnGreater, OnLess

__all__ = ["Action", "ActionError", "Blackboard", "Condition", "ConditionError", "Event", "EventTracker", "MsgPath",
           "OnAny", "OnContainsAll", "OnContainsAny", "OnDifferent", "OnEqual", "OnGreater", "OnLess"]
