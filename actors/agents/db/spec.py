"""The ChromaDB specification: where the store lives and how texts become vectors."""
from __future__ import annotations

import os

import attrs

from emos.config import validators as V

EMBEDDING_BACKENDS = ("sentence-transformers", "ollama")
#: Chroma's three HNSW spaces. "l2" is the *squared* Euclidean distance.
DISTANCES = ("l2", "ip", "cosine")
DEFAULT_PATH = os.path.join(os.path.expanduser("~"), ".cache", "emos", "chroma")


@attrs.define(kw_only=True)
class ChromaDB:
    """Vector DB spec.

    With ``host=None`` (the default) the store is embedded in the calling process and persisted
    under ``path``; with a ``host`` the client talks to a ``chroma run`` server over its HTTP v2
    API. Texts are always embedded client-side by the chosen backend, so Chroma never loads (or
    downloads) an embedding model of its own.
    """

    name: str = attrs.field(default="chroma", validator=V.non_empty_str)
    path: str = attrs.field(default=DEFAULT_PATH, validator=V.non_empty_str,
                            converter=lambda p: os.path.expanduser(p) if isinstance(p, str) else p)
    host: str | None = attrs.field(default=None, validator=attrs.validators.optional(V.non_empty_str))
    port: int = attrs.field(default=8000, validator=V.number(ge=1, le=65535, integer=True, what="a TCP port"))
    tenant: str = attrs.field(default="default_tenant", validator=V.non_empty_str)
    database: str = attrs.field(default="default_database", validator=V.non_empty_str)
    embeddings: str = attrs.field(default="sentence-transformers",
                                  validator=attrs.validators.in_(EMBEDDING_BACKENDS))
    #: sentence-transformers: a local model directory (None = the packaged all-MiniLM-L6-v2);
    #: ollama: the embedding model name.
    checkpoint: str | None = attrs.field(default=None, validator=attrs.validators.optional(V.non_empty_str))
    ollama_host: str = attrs.field(default="127.0.0.1", validator=V.non_empty_str)
    ollama_port: int = attrs.field(default=11434, validator=V.number(ge=1, le=65535, integer=True, what="a TCP port"))
    request_timeout: float = attrs.field(default=30.0, validator=V.number(gt=0, what="a number of seconds"))

    @property
    def is_server(self) -> bool:
        return self.host is not None

    @property
    def server_url(self) -> str:
        """Base URL of the server's v2 API (only meaningful with a host)."""
        return f"http://{self.host}:{self.port}/api/v2"

    @property
    def embedding_checkpoint(self) -> str | None:
        if self.checkpoint is None and self.embeddings == "ollama":
            return "nomic-embed-text"
        return self.checkpoint
