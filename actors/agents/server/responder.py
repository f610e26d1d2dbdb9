"""Deterministic chat responder: scripted replies chosen by regex on the last user message.

A script (YAML or JSON) looks like::

    models: ["llama3.2:3b", "qwen2.5vl:latest"]   # extra names this responder answers to
    rules:
      - match: "(?i)go to the (\\w+)"            # regex searched in the last user message
        tool_call: {name: go_to, arguments: {place: "{1}"}}   # {1} = first regex group
      - match: "at \\[([-\\d.]+), ([-\\d.]+)\\]"           # numbers: a JSON template, parsed after filling
        tool_call: {name: go_to_point, arguments_json: '{{"position": [{1}, {2}]}}'}
      - match: "(?i)hello"
        reply: "Hello! I am a robot."
    default: "You said: {message}"               # optional; {message} = last user text
                                                 # ({turns} in replies: user turns in the request)

A rule with ``tool_call`` applies only when the request offers that tool; otherwise the next
rule is tried. When the last message is a tool result, the reply reports it, so a tool round
trip is testable. Same input, same output: tests and chaos runs can assert on replies.
"""
from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import attrs
import yaml

from ..types import ChatChunk, ChatMessage, ChatRequest, ChatResponse, ToolCall

__all__ = ["ScriptedResponder", "Rule", "load_script"]

DEFAULT_REPLY = "You said: {message}"


@attrs.define(frozen=True)
class Rule:
    pattern: re.Pattern = attrs.field()
    reply: str | None = None
    tool_name: str | None = None
    tool_arguments: dict = attrs.field(factory=dict)
    tool_arguments_json: str | None = None

    def __attrs_post_init__(self) -> None:
        if (self.reply is None) == (self.tool_name is None):
            raise ValueError(f"script rule {self.pattern.pattern!r}: expected exactly one of 'reply' or 'tool_call'")


def _fill(value: Any, match: re.Match, message: str, turns: int = 1) -> Any:
    """Substitute ``{0}``, ``{1}``... (regex groups), ``{message}`` and ``{turns}`` (user turns
    in the request: shows whether chat history reached the model) into strings, recursively."""
    if isinstance(value, str):
        groups = [match.group(0), *[g or "" for g in match.groups()]]
        try:
            return value.format(*groups, message=message, turns=turns)
        except (IndexError, KeyError) as exc:
            raise ValueError(f"script template {value!r}: unknown placeholder {exc}") from None
    if isinstance(value, dict):
        return {k: _fill(v, match, message, turns) for k, v in value.items()}
    if isinstance(value, list):
        return [_fill(v, match, message, turns) for v in value]
    return value


def load_script(source: str | Path | dict | None) -> tuple[list[Rule], str, list[str]]:
    """Parse a script file (or dict) into (rules, default reply, extra model names)."""
    if source is None:
        return [], DEFAULT_REPLY, []
    if not isinstance(source, (str, Path)):
        data = source  # already parsed (validated below)
    else:
        path = Path(source)
        if not path.is_file():
            raise FileNotFoundError(f"responder script {str(path)!r} does not exist")
        try:
            data = yaml.safe_load(path.read_text())  # YAML is a superset of JSON
        except yaml.YAMLError as exc:
            raise ValueError(f"responder script {str(path)!r}: not valid YAML/JSON ({exc})") from None
    if not isinstance(data, dict):
        raise ValueError(f"responder script: expected a mapping with 'rules', got {type(data).__name__}")
    rules = []
    for i, raw in enumerate(data.get("rules") or []):
        if not isinstance(raw, dict) or "match" not in raw:
            raise ValueError(f"responder script rule {i}: expected a mapping with 'match', got {raw!r}")
        try:
            pattern = re.compile(str(raw["match"]))
        except re.error as exc:
            raise ValueError(f"responder script rule {i}: bad regex {raw['match']!r} ({exc})") from None
        call = raw.get("tool_call")
        if call is not None and (not isinstance(call, dict) or not call.get("name")):
            raise ValueError(f"responder script rule {i}: tool_call needs a 'name'")
        if call is not None and call.get("arguments") and call.get("arguments_json"):
            raise ValueError(f"responder script rule {i}: tool_call takes 'arguments' or 'arguments_json', not both")
        arguments_json = (call or {}).get("arguments_json")
        if arguments_json is not None and not isinstance(arguments_json, str):
            raise ValueError(f"responder script rule {i}: arguments_json must be a string (a JSON template)")
        rules.append(Rule(pattern, reply=raw.get("reply"), tool_name=None if call is None else call["name"],
                          tool_arguments=(call or {}).get("arguments") or {}, tool_arguments_json=arguments_json))
    models = data.get("models") or []
    if not isinstance(models, list) or not all(isinstance(m, str) for m in models):
        raise ValueError("responder script: 'models' must be a list of names")
    return rules, str(data.get("default", DEFAULT_REPLY)), models


def _words(text: str) -> list[str]:
    """Split into stream pieces that concatenate back to ``text`` exactly."""
    return re.findall(r"\S+\s*|\s+", text) or [""]


class ScriptedResponder:
    """Answers chat requests from a script; see the module docstring for the format."""

    name = "emos-scripted"

    def __init__(self, script: str | Path | dict | None = None) -> None:
        self.rules, self.default, self.aliases = load_script(script)
        self._counter = 0

    def _next_id(self) -> str:
        self._counter += 1
        return f"call_{self._counter:06d}"

    def respond(self, request: ChatRequest, model: str) -> ChatResponse:
        last = request.messages[-1]
        if last.role == "tool":
            text = f"Tool {last.name or last.tool_call_id or 'call'} returned: {last.content or ''}"
            return self._text(text, request, model)
        user = next((m.content or "" for m in reversed(request.messages) if m.role == "user"), "")
        offered = {t.name for t in request.tools}
        for rule in self.rules:
            match = rule.pattern.search(user)
            if match is None:
                continue
            if rule.tool_name is not None:
                if rule.tool_name not in offered:
                    continue
                if rule.tool_arguments_json is not None:
                    filled = _fill(rule.tool_arguments_json, match, user)
                    try:
                        arguments = json.loads(filled)
                    except ValueError:
                        raise ValueError(f"script rule {rule.pattern.pattern!r}: arguments_json filled to invalid JSON {filled!r}") from None
                else:
                    arguments = _fill(rule.tool_arguments, match, user)
                call = ToolCall(id=self._next_id(), name=rule.tool_name, arguments=arguments)
                message = ChatMessage(role="assistant", content=None, tool_calls=[call])
                return ChatResponse(message=message, finish_reason="tool_calls", usage=self._usage(request, ""), model=model)
            turns = sum(1 for m in request.messages if m.role == "user")
            return self._text(_fill(rule.reply, match, user, turns), request, model)
        images = sum(len(m.images) for m in request.messages)
        text = self.default.format(message=user, images=images)
        return self._text(text, request, model)

    def _text(self, text: str, request: ChatRequest, model: str) -> ChatResponse:
        reason = "stop"
        words = _words(text)
        if request.max_tokens is not None and len(words) > request.max_tokens:
            # honour the token budget, one word = one token here
            text, reason = "".join(words[: request.max_tokens]), "length"
        message = ChatMessage(role="assistant", content=text)
        return ChatResponse(message=message, finish_reason=reason, usage=self._usage(request, text), model=model)

    @staticmethod
    def _usage(request: ChatRequest, text: str) -> dict[str, int]:
        prompt = sum(len((m.content or "").split()) for m in request.messages)
        completion = len(text.split())
        return {"prompt_tokens": prompt, "completion_tokens": completion, "total_tokens": prompt + completion}

    def stream(self, request: ChatRequest, model: str) -> Iterator[ChatChunk]:
        response = self.respond(request, model)
        for piece in _words(response.message.content or ""):
            if piece:
                yield ChatChunk(content=piece)
        yield ChatChunk(content="", tool_calls=response.message.tool_calls, done=True,
                        finish_reason=response.finish_reason, usage=response.usage)
