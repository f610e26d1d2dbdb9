"""Shared-memory topics: rings, wake-ups, publishers and subscribers, and the run they belong to."""
from emos.transport.context import RunContext, current, sweep_stale_runs
from emos.transport.pubsub import MessageTooLarge, Publisher, Subscriber, TopicTypeError, list_topics
from emos.transport.waker import Waker

__all__ = ["RunContext", "current", "sweep_stale_runs", "Publisher", "Subscriber", "Waker", "MessageTooLarge", "TopicTypeError", "list_topics"]
