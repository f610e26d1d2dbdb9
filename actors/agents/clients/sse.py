"""Server-sent events: the wire format of OpenAI streaming (``data: {...}`` ... ``data: [DONE]``)."""
from __future__ import annotations

from collections.abc import Iterable, Iterator

__all__ = ["iter_sse_data", "SSE_DONE", "format_sse"]

SSE_DONE = "[DONE]"


def iter_sse_data(lines: Iterable[str]) -> Iterator[str]:
    """Yield the ``data`` payload of each event; multi-line data fields are joined with ``\\n``.

    Comment lines (``:``) and other fields (``event:``, ``id:``, ``retry:``) are skipped, as the
    SSE spec allows; an event ends at a blank line (or at the end of the stream).
    """
    buffer: list[str] = []
    for raw in lines:
        line = raw.rstrip("\r\n")
        if not line:
            if buffer:
                yield "\n".join(buffer)
                buffer = []
            continue
        if line.startswith(":"):
            continue
        field, _, value = line.partition(":")
        if field == "data":
            buffer.append(value[1:] if value.startswith(" ") else value)
    if buffer:
        yield "\n".join(buffer)


def format_sse(payload: str) -> bytes:
    """One SSE event carrying ``payload`` as its data."""
    return b"".join(b"data: " + line.encode() + b"\n" for line in payload.split("\n")) + b"\n"
