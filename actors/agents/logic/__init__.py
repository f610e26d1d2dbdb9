"""Intelligence logic as small pure pieces: prompts, history, RAG, tools, streaming,
preprocessors, detections as text, VLM output parsing, semantic routing and map encoding.

Nothing here starts a process or touches a topic; components wire these pieces to topics.
"""
from .detections import detections_to_text
from .history import ChatHistory
from .map_encoding import MapConfig, MapEncoder, MapLayer
from .preprocess import PreprocessorChain
from .rag import RAGSettings, retrieve, with_context
from .router import LLMRouter, Route, RouteDecision, SemanticRouterConfig, VectorRouter
from .streaming import StreamChunker, chunk_stream
from .templates import PromptBuilder, PromptTemplate, TemplateVariableError
from .tools import ToolArgumentError, ToolError, ToolRegistry, run_tool_loop
from .vlm_tasks import VLMParseError, parse_vlm_output

__all__ = [
    "detections_to_text", "ChatHistory", "MapConfig", "MapEncoder", "MapLayer", "PreprocessorChain",
    "RAGSettings", "retrieve", "with_context", "LLMRouter", "Route", "RouteDecision",
    "SemanticRouterConfig", "VectorRouter", "StreamChunker", "chunk_stream", "PromptBuilder",
    "PromptTemplate", "TemplateVariableError", "ToolArgumentError", "ToolError", "ToolRegistry",
    "run_tool_loop", "VLMParseError", "parse_vlm_output",
]
