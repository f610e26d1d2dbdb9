"""Typed results of vector-store reads."""
from __future__ import annotations

import attrs


@attrs.frozen
class Record:
    """One stored entry."""

    id: str
    document: str | None
    metadata: dict = attrs.field(factory=dict)


@attrs.frozen
class Hit(Record):
    """A query match; ``distance`` is in the collection's space (smaller is closer)."""

    distance: float = 0.0


def hits_from_query(raw: dict, index: int) -> list[Hit]:
    """Hits of the ``index``-th query text of a Chroma query result.

    Chroma returns one list per query text (``ids[[...]]``); taking ``[index]`` here is the fix
    for the original's bug of zipping over the outer list, which yielded one hit only.
    """
    ids = raw["ids"][index]
    docs = (raw.get("documents") or [None])[index] if raw.get("documents") else None
    metas = (raw.get("metadatas") or [None])[index] if raw.get("metadatas") else None
    dists = (raw.get("distances") or [None])[index] if raw.get("distances") else None
    return [
        Hit(
            id=str(ids[i]),
            document=docs[i] if docs is not None else None,
            metadata=dict(metas[i] or {}) if metas is not None else {},
            distance=float(dists[i]) if dists is not None else float("nan"),
        )
        for i in range(len(ids))
    ]


def records_from_get(raw: dict) -> list[Record]:
    ids = raw["ids"]
    docs = raw.get("documents")
    metas = raw.get("metadatas")
    return [
        Record(
            id=str(ids[i]),
            document=docs[i] if docs is not None else None,
            metadata=dict(metas[i] or {}) if metas is not None else {},
        )
        for i in range(len(ids))
    ]
