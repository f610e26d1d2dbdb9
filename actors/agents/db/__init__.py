"""Vector database spec and client (Chroma): embedded on-disk store or a ``chroma run`` server."""
from .spec import DISTANCES, EMBEDDING_BACKENDS, ChromaDB
from .results import Hit, Record
from .client import ChromaClient

__all__ = ["ChromaDB", "ChromaClient", "Hit", "Record", "DISTANCES", "EMBEDDING_BACKENDS"]
