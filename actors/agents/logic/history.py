"""Chat history with a size limit and a reset phrase.

The system prompt is kept outside the rolling window, so trimming or a reset never drops it
(the original's "chat reset" lost it). Images are stripped before a message is remembered:
re-sending every past camera frame would grow each request without bound.
"""
from __future__ import annotations

from ..types import ChatMessage


class ChatHistory:
    def __init__(self, history_size: int = 10, history_reset_phrase: str = "chat reset",
                 system_prompt: str | None = None) -> None:
        if isinstance(history_size, bool) or not isinstance(history_size, int) or history_size < 2:
            raise ValueError(f"history_size: expected an integer >= 2 (a user turn and its answer), got {history_size!r}")
        if not isinstance(history_reset_phrase, str) or not history_reset_phrase.strip():
            raise ValueError("history_reset_phrase: expected a non-empty string")
        self.history_size = history_size
        self.history_reset_phrase = history_reset_phrase
        self.system_prompt = system_prompt
        self._turns: list[ChatMessage] = []

    def is_reset(self, text: str) -> bool:
        """True if a user text is the reset phrase (case and surrounding punctuation ignored)."""
        return text.strip().strip(".!?").strip().lower() == self.history_reset_phrase.strip().lower()

    def reset(self) -> None:
        """Forget the conversation; the system prompt stays."""
        self._turns.clear()

    def add(self, *messages: ChatMessage) -> None:
        for message in messages:
            if not isinstance(message, ChatMessage):
                raise TypeError(f"ChatHistory.add: expected ChatMessage, got {type(message).__name__}")
            if message.role == "system":
                self.system_prompt = message.content
                continue
            self._turns.append(message.text_only())
        self._trim()

    def _trim(self) -> None:
        excess = len(self._turns) - self.history_size
        if excess <= 0:
            return
        turns = self._turns[excess:]
        # Never start the window with a tool result whose assistant call was cut off:
        # OpenAI-compatible servers reject an orphan tool message.
        while turns and turns[0].role == "tool":
            turns.pop(0)
        self._turns = turns

    def messages(self, new: ChatMessage | None = None) -> list[ChatMessage]:
        """System prompt, remembered turns, then ``new`` (kept with its images for this call)."""
        out = [ChatMessage(role="system", content=self.system_prompt)] if self.system_prompt else []
        out += self._turns
        if new is not None:
            out.append(new)
        return out

    def __len__(self) -> int:
        return len(self._turns)
