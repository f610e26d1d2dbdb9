"""``LLM``: text in (plus detections as text), a language model's answer out.

Prompts come from component- and topic-level jinja2 templates; optional chat history (with a
reset phrase), retrieval from a vector DB (RAG), tool calling, and streaming re-cut at
``break_character`` so a TextToSpeech downstream can speak the first sentence while the model
is still writing. A stream that dies half way publishes what was complete so far and never its
unfinished tail as if it were the end of the answer.

Local model: ``enable_local_model=True`` (constructor argument or config field) runs a GGUF
model through llama.cpp inside the component's own process (default: the packaged
SmolLM2-135M-Instruct; ``local_model_path`` for another file). Without a ``model_client`` it is
the component's model; with one it waits as the extra client ``"local"``: the request-level
failover re-sends a request there when the server fails, and the ``fallback_to_local()`` action
switches to it from a fallback ladder. The file is checked in the recipe line (missing or
corrupt: an error naming it). As the component's model it loads in the worker thread at
activation; standing by (``enable_local_model`` beside a server, or a ladder that holds
``fallback_to_local``) it loads and warms in a thread of its own at activation
(``server/local_standby.py``), so neither the activation nor the swap waits for it.
"""
from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

from attrs import define, field

from emos.config import validators as V
from emos.core.fallbacks import component_fallback
from emos.io.topic import Topic
from emos.msgs import geometry as G
from emos.msgs import intelligence as I
from emos.msgs import std as D

from ..db.spec import DISTANCES
from ..errors import GenerationAbandoned, ModelClientError
from ..logic.history import ChatHistory
from ..logic.rag import RAGSettings, retrieve, with_context
from ..logic.streaming import StreamChunker
from ..logic.templates import PromptBuilder, TemplateVariableError
from ..logic.tools import ToolError, ToolRegistry, run_tool_loop
from ..server.local_client import LOCAL_CLIENT, LocalLLMClient, local_client_for
from ..server.local_standby import LocalStandby
from ..types import ChatMessage, ChatRequest, ImageData, ToolSpec
from .base import PRIMARY_CLIENT, ModelComponent, ModelComponentConfig
from .convert import TEXTUAL_TYPES, text_of

LLM_OUTPUTS = (D.String, I.StreamingString, G.PoseStamped, G.Pose, G.Point, G.PointStamped,
               D.Float32, D.Float64, D.Int32, D.Int64, D.Bool, D.Float32MultiArray, D.Float64MultiArray)


def _optional_path(instance: Any, attribute: Any, value: Any) -> None:
    if value is not None and (not isinstance(value, str) or not value.strip()):
        raise ValueError(f"{type(instance).__name__}.{attribute.name} must be None (the packaged model) or the path of "
                         f"a GGUF file, got {value!r}")


@define(kw_only=True)
class LLMConfig(ModelComponentConfig):
    """LLM options (names and defaults as in EmbodiedAgents)."""

    enable_rag: bool = field(default=False)
    collection_name: str | None = field(default=None)
    distance_func: str = field(default="l2", validator=V.in_(DISTANCES))
    n_results: int = field(default=1, validator=V.in_range(1, 1000))
    add_metadata: bool = field(default=False)
    chat_history: bool = field(default=False)
    history_reset_phrase: str = field(default="chat reset")
    history_size: int = field(default=10, validator=V.in_range(2, 10_000))
    temperature: float = field(default=0.8, validator=V.in_range(0.0, 2.0))
    max_new_tokens: int = field(default=500, validator=V.in_range(1, 10_000_000))
    stream: bool = field(default=False)
    break_character: str = field(default=".")
    system_prompt: str | None = field(default=None)
    max_tool_rounds: int = field(default=4, validator=V.in_range(1, 100))
    #: run a GGUF model in this component's process (see the module docstring)
    enable_local_model: bool = field(default=False)
    #: the GGUF file of the local model; None = the packaged SmolLM2-135M-Instruct
    local_model_path: str | None = field(default=None, validator=_optional_path)
    #: llama.cpp threads of the local model; None = 1 (llama_backend.default_threads: no OpenMP barriers)
    ncpu_local_model: int | None = field(default=None, validator=V.number(ge=1, le=256, integer=True, allow_none=True))
    #: context window of the local model in tokens (prompt + answer)
    local_model_context: int = field(default=2048, validator=V.number(ge=256, le=131072, integer=True))

    def __attrs_post_init__(self) -> None:
        if self.enable_rag and not self.collection_name:
            raise ValueError("LLMConfig: enable_rag=True needs a collection_name to retrieve from")

    @property
    def rag(self) -> RAGSettings:
        return RAGSettings(enable_rag=self.enable_rag, collection_name=self.collection_name,
                           distance_func=self.distance_func, n_results=self.n_results, add_metadata=self.add_metadata)


class LLM(ModelComponent):
    CONFIG_CLASS: ClassVar[type] = LLMConfig
    ALLOWED_INPUTS: ClassVar[tuple[type, ...]] = TEXTUAL_TYPES
    ALLOWED_OUTPUTS: ClassVar[tuple[type, ...]] = LLM_OUTPUTS

    def __init__(self, *, inputs: list[Topic], outputs: list[Topic], model_client: Any = None, config: LLMConfig | None = None,
                 db_client: Any = None, trigger: Any = 1.0, component_name: str, enable_local_model: bool | None = None,
                 **kwargs: Any) -> None:
        if enable_local_model is not None:
            if not isinstance(enable_local_model, bool):
                raise TypeError(f"component {component_name!r}: enable_local_model must be True or False, "
                                f"got {enable_local_model!r}")
            if config is None:
                config = type(self).CONFIG_CLASS()  # LLMConfig, or the subclass's (VLMConfig)
            assert config is not None
            config.enable_local_model = enable_local_model
        local = None
        if config is not None and getattr(config, "enable_local_model", False):
            # Checked here so the recipe line names a missing or corrupt model file.
            local = self._local_client(config, component_name)
            if model_client is None:
                model_client = local
        super().__init__(inputs=inputs, outputs=outputs, model_client=model_client, config=config, db_client=db_client,
                         trigger=trigger, component_name=component_name, **kwargs)
        self.config: LLMConfig
        if local is not None and local is not model_client:
            self._clients[LOCAL_CLIENT] = local
        if self.config.enable_rag and db_client is None:
            raise ValueError(f"component {component_name!r}: enable_rag=True needs a db_client")
        if not any(issubclass(t.msg_type, TEXTUAL_TYPES) for t in self.input_topics):
            raise ValueError(f"component {component_name!r}: {type(self).__name__} needs at least one text input "
                             "(String, StreamingString, Detections or Trackings)")
        if not self.out_topics:
            raise ValueError(f"component {component_name!r}: {type(self).__name__} needs at least one output topic")
        self._prompts = PromptBuilder([self.variable_name(t) for t in self.text_inputs])
        self._tools = ToolRegistry()
        self._history: ChatHistory | None = None
        #: the local model loading / loaded ahead of a failover (see activate_resources)
        self._standby: LocalStandby | None = None
        #: the local client a ladder's fallback_to_local will switch to (not a request-level
        #: backup: the ladder, not the failover, decides when the component goes local)
        self._ladder_local: LocalLLMClient | None = None

    # ------------------------------------------------------------------ local model
    @staticmethod
    def _local_client(config: Any, component_name: str) -> LocalLLMClient:
        try:
            return local_client_for(config.local_model_path, config.ncpu_local_model, config.local_model_context)
        except (ValueError, ImportError) as exc:  # LocalModelError, LocalModelUnavailable
            raise type(exc)(f"component {component_name!r}: local model: {exc}") from None

    @property
    def additional_model_clients(self) -> dict[str, Any]:
        return ModelComponent.additional_model_clients.fget(self)  # type: ignore[attr-defined]

    @additional_model_clients.setter
    def additional_model_clients(self, clients: Mapping[str, Any]) -> None:
        local = self._clients.get(LOCAL_CLIENT)
        ModelComponent.additional_model_clients.fset(self, clients)  # type: ignore[attr-defined]
        if local is not None and LOCAL_CLIENT not in self._clients:  # the local model stays available
            self._clients[LOCAL_CLIENT] = local

    @property
    def local_model_client(self) -> LocalLLMClient | None:
        """The in-process model client, if this component has one (primary or ``"local"``)."""
        return next((c for c in self._clients.values() if isinstance(c, LocalLLMClient)), None)

    @component_fallback
    def fallback_to_local(self) -> bool:
        """Fallback action: answer with the local GGUF model from now on (a recipe's ladder can
        put it after, or instead of, reconnecting to a dead model server). Returns at once (it
        runs on the event loop); the model loads in the worker thread if it is not loaded yet,
        before the next request. ``change_model_client("primary")`` switches back."""
        local = self.local_model_client
        if local is None:
            local = self._ladder_local  # loaded (or loading) since activation
            if local is None:
                try:
                    local = self._local_client(self.config, self.component_name)
                except (ValueError, ImportError) as exc:
                    self._errors("local", "[%s] fallback_to_local: %s", self.component_name, exc)
                    return False
            self._clients[LOCAL_CLIENT] = local
        name = next(n for n, c in self._clients.items() if c is local)
        standby = self._standby
        if standby is not None and standby.error is not None:
            self.get_logger().warning("[%s] fallback_to_local: the local model failed to load at activation (%s); "
                                      "loading it again", self.component_name, standby.error)
        if not self.change_model_client(name):
            return False
        worker = self._worker
        if worker is not None and not self._client_ready:
            # Connects it in the worker before the next question (waits for a load in
            # progress in the standby thread, or loads the model if it is not loaded yet).
            worker.submit(self._reconnect_in_worker)
        return True

    def local_model_state(self) -> dict[str, Any]:
        """Where the local model is (for ``emos call``, the web UI, benchmarks and tests):
        ``role`` "model", "standby" or "none"; ``active``: whether it answers now; ``loaded``;
        ``error``: why the standby load failed; ``load_s``/``warm_s``: how long it took."""
        local = self.local_model_client or self._ladder_local
        standby = self._standby
        role = "none" if local is None else ("model" if local is self._clients.get(PRIMARY_CLIENT) else "standby")
        return {"role": role, "active": local is not None and local is self.model_client,
                "loaded": bool(local is not None and local.loaded),
                "error": standby.error if standby is not None else None,
                "load_s": standby.load_s if standby is not None else None,
                "warm_s": standby.warm_s if standby is not None else None}

    def _ladder_holds_fallback_to_local(self) -> bool:
        return any(getattr(action, "method_name", None) == "fallback_to_local"
                   and getattr(action, "component", None) == self.component_name
                   for fallback in self.fallbacks.values() for action in fallback.steps)

    def _standby_client(self) -> LocalLLMClient | None:
        """The local client to load ahead of a failover, or None (none wanted, or it is the
        component's own model, which the worker loads as any model client)."""
        if isinstance(self._clients.get(PRIMARY_CLIENT), LocalLLMClient):
            return None
        local = self._clients.get(LOCAL_CLIENT)
        if local is None and self._ladder_holds_fallback_to_local():
            if self._ladder_local is None:
                try:
                    self._ladder_local = self._local_client(self.config, self.component_name)
                except (ValueError, ImportError) as exc:  # reported; fallback_to_local reports it again
                    self.get_logger().error("[%s] the ladder holds fallback_to_local() but the local model cannot be "
                                            "used: %s", self.component_name, exc)
                    return None
            local = self._ladder_local
        return local if isinstance(local, LocalLLMClient) else None

    def activate_resources(self) -> None:
        super().activate_resources()
        self._activate_history()
        local = self._standby_client()
        if local is not None and not local.loaded and self._standby is None:
            # Standing by for a failover: loaded and warmed now, in a thread of its own, so
            # neither the activation nor the first questions to the server wait for it.
            self._standby = LocalStandby(local, self.component_name, self.get_logger(), self.config.system_prompt)
            self._standby.start()

    # ------------------------------------------------------------------ recipe API
    @property
    def text_inputs(self) -> list[Topic]:
        return [t for t in self.input_topics if issubclass(t.msg_type, TEXTUAL_TYPES)]

    def set_component_prompt(self, template: str | os.PathLike) -> None:
        """A jinja2 template (string or file) composing the prompt from the text inputs, each
        available under its topic name (``{{ text0 }}``)."""
        self._prompts.set_component_prompt(template)

    def set_topic_prompt(self, input_topic: Topic | str, template: str | os.PathLike) -> None:
        """A jinja2 template wrapping one input's text; its variable is the topic name."""
        name = input_topic.name if isinstance(input_topic, Topic) else input_topic
        self._prompts.set_topic_prompt(name.lstrip("/"), template)

    def set_system_prompt(self, prompt: str) -> None:
        self.config.system_prompt = prompt

    def register_tool(self, tool: Callable[..., Any], tool_description: dict | ToolSpec,
                      send_tool_response_to_model: bool = False) -> None:
        """Offer ``tool`` to the model. With ``send_tool_response_to_model=False`` its return
        value is published as the component's output."""
        self._tools.register_tool(tool, tool_description, send_tool_response_to_model)

    # ------------------------------------------------------------------ steps
    def release_resources(self) -> None:
        super().release_resources()
        standby, self._standby = self._standby, None
        if standby is not None:
            standby.stop()  # a load in progress ends before the model is freed
        clients = list(self._clients.values()) + [self._ladder_local]
        for client in {id(c): c for c in clients if isinstance(c, LocalLLMClient)}.values():
            client.deinitialize()  # frees the model's memory; reloaded at the next activation

    def _activate_history(self) -> None:
        cfg = self.config
        self._history = ChatHistory(cfg.history_size, cfg.history_reset_phrase, cfg.system_prompt) if cfg.chat_history else None

    def missing_inputs(self, inputs: Mapping[str, Any]) -> list[str]:
        if any(t.name in inputs for t in self.text_inputs):
            return []
        return [t.name for t in self.text_inputs]

    def _texts(self, inputs: dict[str, Any]) -> dict[str, str]:
        return {self.variable_name(t): text_of(inputs[t.name]) for t in self.text_inputs if t.name in inputs}

    def prepare(self, inputs: dict[str, Any], trigger: Topic | None) -> Callable[[], None] | None:
        texts = self._texts(inputs)
        if trigger is not None and issubclass(trigger.msg_type, TEXTUAL_TYPES) and not texts.get(self.variable_name(trigger), "").strip():
            return None  # an empty query asks nothing
        if self.config.chat_history and self._history is not None and any(self._history.is_reset(t) for t in texts.values()):
            self._history.reset()
            self.get_logger().info("[%s] chat history reset", self.component_name)
            return None
        try:
            prompt = self._prompts.build(texts)
        except TemplateVariableError as exc:
            self.health_status.set_fail_algorithm(algorithm_names=["prompt_template"], message=str(exc))
            self._errors("template", "[%s] %s", self.component_name, exc)
            return None
        try:
            images = self.images(inputs)
        except ValueError as exc:  # bad image on an input: a system-level failure of that topic
            self.health_status.set_fail_system(topic_names=[getattr(exc, "topic", "image")], message=str(exc))
            self._errors("image", "[%s] %s", self.component_name, exc)
            return None
        if images is None:
            return None
        query = " ".join(texts.values())
        return lambda: self._answer(prompt, query, images)

    def images(self, inputs: dict[str, Any]) -> list[ImageData] | None:
        """Images sent with the prompt (the LLM has none; MLLM overrides)."""
        return []

    def _build_request(self, prompt: str, query: str, images: list[ImageData]) -> tuple[ChatRequest, ChatMessage]:
        context = ""
        if self.config.enable_rag:
            context = retrieve(self.db_client, self.config.rag, query)
        user = ChatMessage(role="user", content=with_context(context, prompt), images=images)
        if self._history is not None:
            messages = self._history.messages(user)
        else:
            messages = ([ChatMessage(role="system", content=self.config.system_prompt)] if self.config.system_prompt else []) + [user]
        request = ChatRequest(messages=messages, temperature=self.config.temperature, max_tokens=self.config.max_new_tokens,
                              stream=self.config.stream and not len(self._tools))
        return request, user

    def _answer(self, prompt: str, query: str, images: list[ImageData]) -> None:
        try:
            request, user = self._build_request(prompt, query, images)
        except Exception as exc:  # the vector DB failed: report, keep serving
            self.health_status.set_fail_component(component_names=[self.component_name], message=f"RAG retrieval failed: {exc}")
            self._errors("rag", "[%s] RAG retrieval from %r failed: %s", self.component_name, self.config.collection_name, exc)
            return
        if len(self._tools):
            self._answer_with_tools(request, user)
        elif request.stream:
            self._answer_streamed(request, user)
        else:
            response = self.call_model(lambda client: client.chat(request))
            self.deliver(response.message.content or "", user)

    def deliver(self, text: str, user: ChatMessage) -> None:
        """Publish a complete answer on every output and remember it."""
        if not text.strip():
            self.health_status.set_fail_algorithm(algorithm_names=[self.model_client_name], message="the model answered nothing")
            self._errors("empty", "[%s] the model answered with empty text; nothing published", self.component_name)
            return
        self.publish_all(self.transform_answer(text))
        self._remember(user, text)
        self.health_status.set_healthy()

    def transform_answer(self, text: str) -> Any:
        """What is published for a complete answer (MLLM tasks parse it)."""
        return text

    def _remember(self, user: ChatMessage, answer: str | None, exchange: list[ChatMessage] | None = None) -> None:
        if self._history is None:
            return
        self._history.add(user, *(exchange or [ChatMessage(role="assistant", content=answer or "")]))

    def _answer_with_tools(self, request: ChatRequest, user: ChatMessage) -> None:
        chat = lambda req: self.call_model(lambda client: client.chat(req))  # noqa: E731
        try:
            result = run_tool_loop(chat, request, self._tools, max_rounds=self.config.max_tool_rounds)
        except ToolError as exc:  # unknown tool, arguments that do not match the schema, tool raised
            self.health_status.set_fail_algorithm(algorithm_names=["tool_calling"], message=str(exc))
            self._errors("tool", "[%s] %s", self.component_name, exc)
            return
        output = result.output
        if output is None or (isinstance(output, str) and not output.strip()):
            self.health_status.set_fail_algorithm(algorithm_names=["tool_calling"], message="no answer and no tool result")
            return
        self.publish_all(output)
        self._remember(user, None, result.messages)
        self.health_status.set_healthy()

    def _answer_streamed(self, request: ChatRequest, user: ChatMessage) -> None:
        published: list[str] = []

        def send(client: Any) -> None:
            chunker = StreamChunker(self.config.break_character)
            for chunk in client.chat_stream(request):
                for piece in chunker.feed(chunk.content):
                    self._publish_piece(piece, done=False)
                    published.append(piece)
            # Reached only when the stream ended properly: the tail is complete text.
            tail = chunker.flush()
            for piece in tail:
                published.append(piece)
            self._publish_piece(tail[0] if tail else "", done=True)

        try:
            # Before the first piece went out, a failed stream can be re-sent (or sent to a backup);
            # after it, re-sending would repeat text downstream has already spoken.
            self.call_model(send, retry_allowed=lambda: not published)
        except GenerationAbandoned as exc:  # switched clients after part of it went out: end it there
            self._publish_piece("", done=True)
            self.get_logger().info("[%s] %s (after %d piece(s))", self.component_name, exc, len(published))
            return
        except ModelClientError as exc:
            if published:
                self.health_status.set_fail_algorithm(algorithm_names=[self.model_client_name],
                                                      message=f"stream broke after {len(published)} piece(s): {exc}")
                self._errors("stream", "[%s] the stream broke after %d piece(s); the unfinished rest was dropped: %s",
                             self.component_name, len(published), exc)
                return
            raise
        self._remember(user, " ".join(published))
        self.health_status.set_healthy()

    def _publish_piece(self, piece: str, done: bool) -> None:
        for topic in self.out_topics:
            if issubclass(topic.msg_type, I.StreamingString):
                self.publish_output(topic, I.StreamingString(stream=True, done=done, data=piece))
            elif piece:
                self.publish_output(topic, piece) if issubclass(topic.msg_type, D.String) else None

    def warmup(self) -> None:
        self.model_client.chat(ChatRequest(messages=[ChatMessage(role="user", content="hello")], max_tokens=8))
