"""Events, conditions and actions: what the runtime reacts to, and how."""
from emos.events.action import Action, ActionError
from emos.events.conditions import Condition, ConditionError, MsgPath
from emos.events.event import Blackboard, Event, EventTracker

__all__ = ["Action", "ActionError", "Blackboard", "Condition", "ConditionError", "Event", "EventTracker", "MsgPath"]
