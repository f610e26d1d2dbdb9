"""Tool registration and the tool-calling loop.

With ``send_tool_response_to_model=True`` a tool's result goes back to the model as a ``tool``
message and the model is called again (calculator-style tools). With False the tool's return
value *is* the output (the model only fills in structured arguments, as in the Go-to-X recipe).
Arguments are validated against the tool's JSON schema before the tool runs.
"""
from __future__ import annotations

import inspect
import json
from collections.abc import Callable
from typing import Any

import attrs

from emos.errors import EmosError

from ..types import ChatMessage, ChatRequest, ChatResponse, ToolCall, ToolSpec

# Python-style type names that recipes write in schemas ("list[float]" in the tool-calling
# recipe); models and validators only understand JSON-schema types, so they are translated.
_PY_TYPES = {"str": "string", "string": "string", "float": "number", "number": "number", "int": "integer",
             "integer": "integer", "bool": "boolean", "boolean": "boolean", "dict": "object",
             "object": "object", "list": "array", "array": "array", "none": "null", "null": "null"}


class ToolError(EmosError, RuntimeError):
    """A tool call could not be carried out."""


class ToolArgumentError(ToolError, ValueError):
    """The model's arguments do not match the tool's schema."""


def _normalize_type(value: Any) -> dict:
    if not isinstance(value, str):
        return {"type": value}
    text = value.strip().lower().replace(" ", "")
    for prefix in ("list[", "array["):
        if text.startswith(prefix) and text.endswith("]"):
            return {"type": "array", "items": _normalize_type(text[len(prefix):-1])}
    if text not in _PY_TYPES:
        raise ValueError(f"unknown parameter type {value!r}; expected a JSON-schema type or e.g. 'list[float]'")
    return {"type": _PY_TYPES[text]}


def normalize_schema(schema: dict) -> dict:
    """A JSON schema with python-style type names translated (recursively)."""
    out = {}
    for key, value in schema.items():
        if key == "type":
            out.update(_normalize_type(value))
        elif key == "properties" and isinstance(value, dict):
            out[key] = {name: normalize_schema(prop) if isinstance(prop, dict) else prop for name, prop in value.items()}
        elif key == "items" and isinstance(value, dict):
            out[key] = normalize_schema(value)
        else:
            out[key] = value
    return out


def tool_spec_from_description(description: dict | ToolSpec) -> ToolSpec:
    """A ToolSpec from an OpenAI/Ollama-style description dict (``{"type": "function", ...}``)."""
    if isinstance(description, ToolSpec):
        return attrs.evolve(description, parameters=normalize_schema(description.parameters))
    if not isinstance(description, dict):
        raise TypeError(f"tool_description: expected a dict or ToolSpec, got {type(description).__name__}")
    function = description.get("function", description)
    if not isinstance(function, dict) or not function.get("name"):
        raise ValueError("tool_description: expected {'type': 'function', 'function': {'name': ..., ...}}")
    parameters = normalize_schema(dict(function.get("parameters") or {"type": "object", "properties": {}}))
    # The recipe puts "required" beside "parameters" instead of inside it: honour both.
    required = function.get("required")
    if required and "required" not in parameters:
        parameters["required"] = list(required)
    return ToolSpec(name=function["name"], description=function.get("description", ""), parameters=parameters)


@attrs.define
class RegisteredTool:
    function: Callable[..., Any]
    spec: ToolSpec
    send_tool_response_to_model: bool


@attrs.frozen
class ToolResult:
    call: ToolCall
    value: Any
    send_to_model: bool


class ToolRegistry:
    def __init__(self) -> None:
        self._tools: dict[str, RegisteredTool] = {}

    def register_tool(self, tool: Callable[..., Any], tool_description: dict | ToolSpec,
                      send_tool_response_to_model: bool = False) -> ToolSpec:
        if not callable(tool):
            raise TypeError(f"register_tool: tool must be callable, got {type(tool).__name__}")
        spec = tool_spec_from_description(tool_description)
        _validator(spec)  # a broken schema fails at registration, not at the first call
        params = set((spec.parameters.get("properties") or {}).keys())
        try:
            signature = inspect.signature(tool)
            accepts_kwargs = any(p.kind is p.VAR_KEYWORD for p in signature.parameters.values())
            unknown = params - set(signature.parameters) if not accepts_kwargs else set()
        except ValueError:
            unknown = set()
        if unknown:
            raise ValueError(f"tool {spec.name!r}: schema parameters {sorted(unknown)} are not arguments of "
                             f"{getattr(tool, '__name__', tool)!r}")
        self._tools[spec.name] = RegisteredTool(tool, spec, bool(send_tool_response_to_model))
        return spec

    @property
    def specs(self) -> list[ToolSpec]:
        return [t.spec for t in self._tools.values()]

    def __contains__(self, name: str) -> bool:
        return name in self._tools

    def __len__(self) -> int:
        return len(self._tools)

    def validate(self, call: ToolCall) -> RegisteredTool:
        tool = self._tools.get(call.name)
        if tool is None:
            raise ToolError(f"the model called unknown tool {call.name!r}; registered: {sorted(self._tools)}")
        errors = sorted(_validator(tool.spec).iter_errors(call.arguments), key=lambda e: list(e.path))
        if errors:
            detail = "; ".join(f"{'/'.join(map(str, e.path)) or '(arguments)'}: {e.message}" for e in errors)
            raise ToolArgumentError(f"arguments of tool {call.name!r} do not match its schema: {detail}")
        return tool

    def call(self, call: ToolCall) -> ToolResult:
        tool = self.validate(call)
        try:
            value = tool.function(**call.arguments)
        except Exception as exc:
            raise ToolError(f"tool {call.name!r} raised {type(exc).__name__}: {exc}") from exc
        return ToolResult(call, value, tool.send_tool_response_to_model)


def _validator(spec: ToolSpec):
    try:
        import jsonschema
    except ImportError as exc:  # pragma: no cover - jsonschema comes with chromadb
        raise ImportError("tool argument validation needs jsonschema: pip install jsonschema") from exc
    schema = spec.parameters or {"type": "object"}
    try:
        jsonschema.Draft202012Validator.check_schema(schema)
    except jsonschema.SchemaError as exc:
        raise ValueError(f"tool {spec.name!r}: invalid JSON schema for parameters: {exc.message}") from None
    return jsonschema.Draft202012Validator(schema)


def _tool_message(result: ToolResult) -> ChatMessage:
    value = result.value
    if hasattr(value, "tolist"):  # numpy results
        value = value.tolist()
    content = value if isinstance(value, str) else json.dumps(value, default=str)
    return ChatMessage(role="tool", content=content, tool_call_id=result.call.id, name=result.call.name)


@attrs.frozen
class ToolLoopOutput:
    """What the component publishes: the model text, or the direct tool value(s)."""

    text: str | None
    tool_values: list[Any]
    messages: list[ChatMessage]  # the whole exchange, for chat history

    @property
    def output(self) -> Any:
        if self.tool_values:
            return self.tool_values[0] if len(self.tool_values) == 1 else self.tool_values
        return self.text


def run_tool_loop(chat: Callable[[ChatRequest], ChatResponse], request: ChatRequest,
                  registry: ToolRegistry, max_rounds: int = 4) -> ToolLoopOutput:
    """Call the model with the registry's tools until it answers without tool calls.

    A round whose calls include a tool with ``send_tool_response_to_model=False`` ends the loop
    and returns those tools' values as the output. Bad arguments for such a tool raise
    ToolArgumentError; for tools whose result goes back to the model, the error goes back as the
    tool message so the model can correct itself.
    """
    if max_rounds < 1:
        raise ValueError(f"max_rounds: expected >= 1, got {max_rounds}")
    request = attrs.evolve(request, tools=registry.specs, messages=list(request.messages))
    exchange: list[ChatMessage] = []
    for _ in range(max_rounds):
        response = chat(request)
        message = response.message
        exchange.append(message.text_only())
        if not message.tool_calls:
            return ToolLoopOutput(message.content, [], exchange)
        direct, replies = [], []
        for call in message.tool_calls:
            tool = registry._tools.get(call.name)
            if tool is not None and not tool.send_tool_response_to_model:
                direct.append(registry.call(call).value)
                continue
            try:
                replies.append(_tool_message(registry.call(call)))
            except ToolError as exc:
                replies.append(ChatMessage(role="tool", content=f"error: {exc}", tool_call_id=call.id, name=call.name))
        exchange += replies
        if direct:
            return ToolLoopOutput(None, direct, exchange)
        request = attrs.evolve(request, messages=request.messages + [message, *replies])
    raise ToolError(f"the model was still calling tools after {max_rounds} rounds")
