"""Vector database spec and client (Chroma): embedded on-disk store or a ``chroma run`` server."""
from .client import ChromaClient
from .results import Hit, Record
from .spec import DISTANCES, EMBEDDING_BACKENDS, ChromaDB

__all__ = ["ChromaDB", "ChromaClient", "Hit", "Record", "DISTANCES", "EMBEDDING_BACKENDS"]
