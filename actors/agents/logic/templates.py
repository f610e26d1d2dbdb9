"""jinja2 prompt templates at component and topic level.

A template is a string or a file path. Variables are topic names (``{{ text0 }}``); a template
asking for a variable that is not provided is an error naming the missing variables, never a
silently empty prompt (jinja2's default would render "" for it).
"""
from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

from emos.errors import EmosError

_TEMPLATE_SUFFIXES = (".jinja", ".jinja2", ".j2", ".txt", ".tmpl")


class TemplateVariableError(EmosError, ValueError):
    """A template needs variables that were not given."""


def _environment():
    try:
        import jinja2
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("prompt templates need jinja2: pip install 'emos[agents]'") from exc
    # StrictUndefined: a typo in a variable name must fail loudly, not render as "".
    return jinja2, jinja2.Environment(undefined=jinja2.StrictUndefined, autoescape=False,
                                      keep_trailing_newline=True)


def _looks_like_path(template: str) -> bool:
    return "\n" not in template and "{" not in template and (
        template.endswith(_TEMPLATE_SUFFIXES) or os.path.isfile(template))


class PromptTemplate:
    """A compiled jinja2 template from a string or a file (``Path`` or a path-like string)."""

    def __init__(self, template: str | os.PathLike, name: str = "prompt") -> None:
        if isinstance(template, os.PathLike) or (isinstance(template, str) and _looks_like_path(template)):
            path = Path(template)
            if not path.is_file():
                raise FileNotFoundError(f"{name} template file {str(path)!r} does not exist")
            source = path.read_text(encoding="utf-8")
        elif isinstance(template, str):
            source = template
        else:
            raise TypeError(f"{name} template: expected a string or a file path, got {type(template).__name__}")
        if not source.strip():
            raise ValueError(f"{name} template is empty")
        jinja2, env = _environment()
        from jinja2 import meta

        try:
            self._template = env.from_string(source)
            self.variables: frozenset[str] = frozenset(meta.find_undeclared_variables(env.parse(source)))
        except jinja2.TemplateSyntaxError as exc:
            raise ValueError(f"{name} template has a jinja2 syntax error on line {exc.lineno}: {exc.message}") from None
        self.name = name
        self.source = source

    def check_variables(self, available: set[str] | frozenset[str]) -> None:
        """Raise now (at definition time) if the template uses names that will never exist."""
        missing = sorted(self.variables - set(available))
        if missing:
            raise TemplateVariableError(
                f"{self.name} template uses {missing}, but only {sorted(available)} are available")

    def render(self, variables: Mapping[str, object]) -> str:
        missing = sorted(v for v in self.variables if v not in variables)
        if missing:
            raise TemplateVariableError(f"{self.name} template needs {missing}; got {sorted(variables)}")
        return self._template.render(**variables)


class PromptBuilder:
    """Builds the model prompt from the latest text of each input topic.

    - a topic-level template wraps that topic's text (its variable is the topic name);
    - a component-level template, if set, composes the final prompt from all topic texts
      (after their topic templates); otherwise the topic texts are joined in input order.
    """

    def __init__(self, topic_names: list[str] | None = None) -> None:
        self.topic_names = list(topic_names) if topic_names is not None else None
        self.component: PromptTemplate | None = None
        self.topics: dict[str, PromptTemplate] = {}

    def set_component_prompt(self, template: str | os.PathLike) -> None:
        compiled = PromptTemplate(template, name="component prompt")
        if self.topic_names is not None:
            compiled.check_variables(set(self.topic_names))
        self.component = compiled

    def set_topic_prompt(self, topic: str | object, template: str | os.PathLike) -> None:
        name = topic if isinstance(topic, str) else getattr(topic, "name", None)
        if not isinstance(name, str):
            raise TypeError(f"set_topic_prompt: expected a topic or topic name, got {type(topic).__name__}")
        if self.topic_names is not None and name not in self.topic_names:
            raise ValueError(f"set_topic_prompt: {name!r} is not an input topic; inputs are {self.topic_names}")
        compiled = PromptTemplate(template, name=f"topic {name!r} prompt")
        compiled.check_variables({name})
        self.topics[name] = compiled

    def build(self, texts: Mapping[str, str]) -> str:
        """The prompt for one model call; ``texts`` maps topic name -> latest text."""
        rendered = {name: (self.topics[name].render({name: text}) if name in self.topics else text)
                    for name, text in texts.items()}
        if self.component is not None:
            return self.component.render(rendered)
        order = self.topic_names or list(rendered)
        return "\n".join(rendered[n] for n in order if n in rendered)
