"""Retrieval-augmented generation: fetch context from the vector DB and put it before the query."""
from __future__ import annotations

import json
from typing import Protocol

import attrs

from emos.config import validators as V

from ..db.results import Hit
from ..db.spec import DISTANCES


class VectorStore(Protocol):
    def query(self, collection_name: str, query: str, n_results: int = 1, distance_func: str = "l2",
              where: dict | None = None) -> list[Hit]: ...


@attrs.define(kw_only=True)
class RAGSettings:
    """The LLMConfig fields that drive retrieval (same names and defaults)."""

    enable_rag: bool = attrs.field(default=False, validator=attrs.validators.instance_of(bool))
    collection_name: str | None = attrs.field(default=None)
    distance_func: str = attrs.field(default="l2", validator=attrs.validators.in_(DISTANCES))
    n_results: int = attrs.field(default=1, validator=V.int_at_least(1))
    add_metadata: bool = attrs.field(default=False, validator=attrs.validators.instance_of(bool))

    def __attrs_post_init__(self) -> None:
        if self.enable_rag and not self.collection_name:
            raise ValueError("enable_rag=True needs a collection_name to retrieve from")


def format_hits(hits: list[Hit], add_metadata: bool) -> str:
    """One line per hit: its document, followed by its metadata as JSON when asked."""
    lines = []
    for hit in hits:
        line = hit.document or ""
        if add_metadata and hit.metadata:
            line = f"{line}, {json.dumps(hit.metadata, sort_keys=True, default=str)}" if line else \
                json.dumps(hit.metadata, sort_keys=True, default=str)
        if line:
            lines.append(line)
    return "\n".join(lines)


def retrieve(store: VectorStore, settings: RAGSettings, query: str) -> str:
    """The context text for ``query`` ("" when RAG is off or nothing is stored)."""
    if not settings.enable_rag or settings.collection_name is None:
        return ""
    hits = store.query(settings.collection_name, query, n_results=settings.n_results,
                       distance_func=settings.distance_func)
    return format_hits(hits, settings.add_metadata)


def with_context(context: str, prompt: str) -> str:
    """Context first, then the prompt: the model reads the facts before the question."""
    if not context:
        return prompt
    return f"{context}\n{prompt}" if prompt else context
