"""Config files (YAML, TOML, JSON) into attrs configs, with errors that name file, key and type.

A file holds a common section ``"/**"`` applied to every component, then one section per
component name; the component's own section wins over the common one. ``inputs`` and
``outputs`` sub-sections describe topics and are returned separately.
"""
from __future__ import annotations

import json
import typing
from enum import Enum
from pathlib import Path
from typing import Any

import attrs
import numpy as np

from emos.errors import ConfigError as ConfigError  # defined with the exception tree; still importable from here

COMMON_SECTION = "/**"
TOPIC_SECTIONS = ("inputs", "outputs")


def read_config_file(path: str | Path) -> dict[str, Any]:
    """Parse a YAML, TOML or JSON file into a mapping (format chosen by extension)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config file {path} does not exist")
    text = path.read_text()
    suffix = path.suffix.lower()
    try:
        if suffix in (".yaml", ".yml"):
            import yaml

            data = yaml.safe_load(text)
        elif suffix == ".toml":
            import tomllib

            data = tomllib.loads(text)
        elif suffix == ".json":
            data = json.loads(text)
        else:
            raise ConfigError(f"config file {path}: unknown format {suffix!r}; use .yaml, .yml, .toml or .json")
    except ConfigError:
        raise
    except Exception as exc:  # each parser has its own error type; all mean "malformed"
        raise ConfigError(f"config file {path} is not valid {suffix[1:].upper()}: {exc}") from exc
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"config file {path}: top level must be a mapping of sections, got {type(data).__name__}")
    return data


def component_section(data: dict[str, Any], component_name: str) -> dict[str, Any]:
    """The merged ``/**`` + ``component_name`` section."""
    merged: dict[str, Any] = {}
    for key in (COMMON_SECTION, component_name, "/" + component_name):
        section = data.get(key)
        if section is None:
            continue
        if not isinstance(section, dict):
            raise ConfigError(f"section {key!r} must be a mapping, got {type(section).__name__}")
        _deep_merge(merged, section)
    return merged


def _deep_merge(into: dict[str, Any], other: dict[str, Any]) -> None:
    for key, value in other.items():
        if isinstance(value, dict) and isinstance(into.get(key), dict):
            _deep_merge(into[key], value)
        else:
            into[key] = value


def apply_mapping(config: Any, data: dict[str, Any], source: str, path: str = "", ignore_unknown: bool = False) -> None:
    """Set ``config``'s fields from ``data`` recursively; every value goes through validators.

    ``ignore_unknown`` lets the common ``/**`` section carry keys only some components have.
    """
    cls = type(config)
    attrs.resolve_types(cls)
    fields = {f.name.lstrip("_") if f.alias is None else f.alias: f for f in attrs.fields(cls)}
    for key, value in data.items():
        where = f"{path}.{key}" if path else key
        fld = fields.get(key)
        if fld is None:
            if ignore_unknown:
                continue
            raise ConfigError(f"{source}: unknown parameter {where!r} for {cls.__name__}; known: {', '.join(sorted(fields))}")
        current = getattr(config, fld.name)
        if attrs.has(type(current)) and isinstance(value, dict) and _is_frozen(current):
            # A frozen record (e.g. RobotFrames) cannot be changed in place: set an evolved copy.
            unknown = sorted(set(value) - {f.name for f in attrs.fields(type(current))})
            if unknown and not ignore_unknown:
                raise ConfigError(f"{source}: unknown parameter(s) {', '.join(f'{where}.{k}' for k in unknown)} "
                                  f"for {type(current).__name__}")
            try:
                value = attrs.evolve(current, **{k: v for k, v in value.items() if k not in unknown})
            except Exception as exc:
                raise ConfigError(f"{source}: {where}: {exc}") from exc
        elif attrs.has(type(current)) and isinstance(value, dict):
            apply_mapping(current, value, source, where, ignore_unknown)
            continue
        elif (target := _target_type(fld.type)) is not None and attrs.has(target) and isinstance(value, dict):
            inner = target() if current is None else current
            apply_mapping(inner, value, source, where, ignore_unknown)
            value = inner
        else:
            value = _coerce(value, _target_type(fld.type), source, where)
        try:
            setattr(config, fld.name, value)
        except Exception as exc:
            raise ConfigError(f"{source}: {where}: {exc} (expected {_type_name(fld.type)}, got {value!r})") from exc


def _is_frozen(obj: Any) -> bool:
    from attr._make import _frozen_setattrs  # attrs' frozen classes all use this __setattr__

    setattr_of_class: object = type(obj).__setattr__
    return setattr_of_class is _frozen_setattrs


def _target_type(tp: Any) -> Any:
    if tp is None:
        return None
    origin = typing.get_origin(tp)
    if origin is typing.Union or str(origin) == "<class 'types.UnionType'>":
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return args[0] if len(args) == 1 else None
    return tp


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", None) or str(tp)


def _coerce(value: Any, target: Any, source: str, where: str) -> Any:
    """Turn file values into what the field expects where the conversion is unambiguous."""
    if target is None or not isinstance(target, type):
        if target is not None and typing.get_origin(target) in (list, tuple) and isinstance(value, list):
            return value
        return value
    if issubclass(target, Enum) and isinstance(value, (str, int)):
        for member in target:
            if value == member.value or (isinstance(value, str) and value.lower() in (member.name.lower(), str(member.value).lower())):
                return member
        raise ConfigError(f"{source}: {where}: expected one of {[m.name for m in target]}, got {value!r}")
    if target is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if target is float and not isinstance(value, (int, float)) or target is float and isinstance(value, bool):
        raise ConfigError(f"{source}: {where}: expected float, got {type(value).__name__} {value!r}")
    if target is int and (isinstance(value, bool) or not isinstance(value, int)):
        raise ConfigError(f"{source}: {where}: expected int, got {type(value).__name__} {value!r}")
    if target is bool and not isinstance(value, bool):
        raise ConfigError(f"{source}: {where}: expected bool, got {type(value).__name__} {value!r}")
    if target is str and not isinstance(value, str):
        raise ConfigError(f"{source}: {where}: expected str, got {type(value).__name__} {value!r}")
    if target is np.ndarray and isinstance(value, list):
        return np.asarray(value, dtype=float)
    return value


def load_into(config: Any, config_file: str | Path, component_name: str) -> dict[str, Any]:
    """Apply a file's sections to ``config``; returns its ``inputs``/``outputs`` topic sections."""
    data = read_config_file(config_file)
    common = _section(data, COMMON_SECTION, config_file, "the section every component reads")
    own: dict[str, Any] = {}
    for key in (component_name, "/" + component_name):
        own = _section(data, key, config_file, f"the section of component {component_name}") or own
    topics = {k: own.get(k, common.get(k)) for k in TOPIC_SECTIONS if own.get(k, common.get(k)) is not None}
    common = {k: v for k, v in common.items() if k not in TOPIC_SECTIONS}
    own = {k: v for k, v in own.items() if k not in TOPIC_SECTIONS}
    apply_mapping(config, common, str(config_file), ignore_unknown=True)
    apply_mapping(config, own, str(config_file), path=component_name)
    return topics


def _section(data: dict[str, Any], key: str, source: str | Path, what: str) -> dict[str, Any]:
    """``data[key]`` as a mapping of parameters ({} when absent or empty); anything else is refused,
    since a scalar where parameters belong (``cam: 5``) would otherwise be ignored without a word."""
    section = data.get(key)
    if section is None:
        return {}
    if not isinstance(section, dict):
        raise ConfigError(f"config file {source}: {key!r} is {what} and must be a mapping of parameters "
                          f"(name: value), got {type(section).__name__} {section!r}")
    return section


def section_problems(data: dict[str, Any], component_names: list[str], source: str) -> list[str]:
    """Sections of a config file that no component will read, each with a hint.

    A misspelled component section, or a parameter written at the top level instead of under
    ``/**`` or a component, would otherwise be ignored without a word.
    """
    import difflib

    problems = []
    names = sorted(component_names)
    for key, value in data.items():
        if key == COMMON_SECTION:
            continue
        name = str(key).lstrip("/")
        if name in component_names:
            if value is not None and not isinstance(value, dict):
                problems.append(f"{source}: {key!r} is the section of component {name} and must be a mapping of "
                                f"parameters (name: value), got {type(value).__name__} {value!r}; it is ignored")
            continue
        if not isinstance(value, dict):
            problems.append(
                f"{source}: top-level key {key!r} holds a {type(value).__name__} ({value!r}), not a section; "
                f"parameters go under {COMMON_SECTION!r} or under a component's name ({', '.join(names)})"
            )
            continue
        close = difflib.get_close_matches(name, names, n=3)
        hint = f"did you mean {' or '.join(repr(c) for c in close)}?" if close else f"components: {', '.join(names)}"
        problems.append(f"{source}: section {key!r} matches no component of this system and is ignored; {hint}")
    return problems

