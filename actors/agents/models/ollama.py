"""Spec for models pulled and served by Ollama."""
from __future__ import annotations

import attrs

from .base import Model, options_validator

__all__ = ["OllamaModel"]

# Generation/runtime options Ollama's API accepts in ``options`` (docs/api.md, "valid parameters").
OLLAMA_OPTIONS: dict[str, type] = {
    "num_keep": int,
    "seed": int,
    "num_predict": int,
    "top_k": int,
    "top_p": float,
    "min_p": float,
    "typical_p": float,
    "repeat_last_n": int,
    "temperature": float,
    "repeat_penalty": float,
    "presence_penalty": float,
    "frequency_penalty": float,
    "penalize_newline": bool,
    "stop": list,
    "numa": bool,
    "num_ctx": int,
    "num_batch": int,
    "num_gpu": int,
    "main_gpu": int,
    "use_mmap": bool,
    "num_thread": int,
    "think": bool,
}


def _keep_alive(instance, attribute, value) -> None:
    # Ollama takes a duration string ("5m", "1h", "-1") or seconds as a number; -1/negative = forever.
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise TypeError(f"OllamaModel.keep_alive: expected seconds or a duration string like '5m', got {value!r}")


@attrs.define(kw_only=True)
class OllamaModel(Model):
    """An Ollama tag (``llama3.2:3b``, ``qwen2.5vl:latest``) with default ``options``.

    ``options`` that clash with component settings (``temperature``, ``num_predict``) are
    overridden by the component, as in the original. ``keep_alive`` is how long Ollama keeps
    the model loaded after a request.
    """

    checkpoint: str = attrs.field(default="llama3.2:3b", validator=attrs.validators.instance_of(str))
    options: dict | None = attrs.field(default=None, validator=options_validator(OLLAMA_OPTIONS))
    keep_alive: int | float | str = attrs.field(default="5m", validator=_keep_alive)

    INIT_FIELDS = ("checkpoint", "options")
