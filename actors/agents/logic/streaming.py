"""Chunking a streamed model reply on ``break_character`` so that downstream consumers (TTS)
can start on the first sentence while the model is still writing."""
from __future__ import annotations

from collections.abc import Iterable, Iterator

from ..types import ChatChunk


class StreamChunker:
    """Accumulates streamed text and releases it piece by piece at each ``break_character``."""

    def __init__(self, break_character: str = ".") -> None:
        if not isinstance(break_character, str):
            raise TypeError(f"break_character: expected a string, got {type(break_character).__name__}")
        self.break_character = break_character
        self._buffer = ""

    def feed(self, text: str | None) -> list[str]:
        """Add streamed text (None counts as ""); return the pieces completed by it."""
        if not text:
            return []
        if not self.break_character:  # no chunking: every piece goes out as it arrives
            return [text]
        self._buffer += text
        pieces = []
        while True:
            at = self._buffer.find(self.break_character)
            if at < 0:
                break
            end = at + len(self.break_character)
            piece, self._buffer = self._buffer[:end], self._buffer[end:]
            if piece.strip():
                pieces.append(piece.strip())
        return pieces

    def flush(self) -> list[str]:
        """The remainder at the end of the stream."""
        rest, self._buffer = self._buffer.strip(), ""
        return [rest] if rest else []


def chunk_stream(chunks: Iterable[ChatChunk | str | None], break_character: str = ".") -> Iterator[str]:
    """Re-cut a stream of model chunks into pieces ending at ``break_character``."""
    chunker = StreamChunker(break_character)
    for chunk in chunks:
        text = chunk.content if isinstance(chunk, ChatChunk) else chunk
        yield from chunker.feed(text)
    yield from chunker.flush()
