"""Declarative inputs and outputs."""
from emos.io.topic import Topic, normalize_topic_name

__all__ = ["Topic", "normalize_topic_name"]
