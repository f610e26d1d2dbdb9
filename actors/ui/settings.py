"""Component settings as forms: fields described from the attrs config, changes applied live.

The form of a component is built from its config class (field types, enum choices and the ranges
of ``in_range`` / ``in_`` validators), the current values come from the running component, and
a change goes through :func:`apply_config_change`: the one place the UI changes a running
component's configuration. Today that is the node's control socket
(``update_config_parameters``), which validates in the component's own process and changes
nothing if a value is refused.
"""
from __future__ import annotations

import enum
import typing
from pathlib import Path
from typing import Any

import attrs

from emos.core import control as C
from emos.core.rpc import AsyncRpcClient, RpcConnectionError, RpcError
from emos.errors import EmosError


class SettingRefused(EmosError, ValueError):
    """A setting value that does not fit its field."""


def _validators(v: Any) -> list[Any]:
    if v is None:
        return []
    inner = getattr(v, "_validators", None) or getattr(v, "validators", None)
    if isinstance(inner, (list, tuple)):
        return [x for item in inner for x in _validators(item)]
    return [v]


def _field_type(config_cls: type, fld: attrs.Attribute) -> Any:
    try:
        hints = typing.get_type_hints(config_cls)
    except Exception:
        hints = {}
    return hints.get(fld.name, fld.type)


def describe_field(config_cls: type, fld: attrs.Attribute) -> dict[str, Any]:
    """Widget description of one config field: kind, choices, range, help text."""
    ftype = _field_type(config_cls, fld)
    out: dict[str, Any] = {"name": fld.name, "editable": True}
    origin = typing.get_origin(ftype)
    args = [a for a in typing.get_args(ftype) if a is not type(None)]
    if origin is typing.Union and len(args) == 1:
        ftype, out["optional"] = args[0], True
    if isinstance(ftype, type) and issubclass(ftype, enum.Enum):
        out.update(kind="choice", choices=[m.value if isinstance(m.value, (str, int, float)) else m.name for m in ftype])
    elif ftype is bool:
        out["kind"] = "bool"
    elif ftype is int:
        out["kind"] = "int"
    elif ftype is float:
        out["kind"] = "float"
    elif ftype is str:
        out["kind"] = "str"
    else:
        # Nested configs, arrays and lists: shown, changed through config files or services.
        out.update(kind="json", editable=False)
    for v in _validators(fld.validator):
        if hasattr(v, "emos_range"):
            out["min"], out["max"] = v.emos_range
        if hasattr(v, "emos_choices"):
            out.update(kind="choice", choices=list(v.emos_choices))
    doc = (fld.metadata or {}).get("description") or (fld.metadata or {}).get("help")
    if doc:
        out["help"] = str(doc)
    return out


def describe_config(config: Any) -> list[dict[str, Any]]:
    cls = type(config)
    return [describe_field(cls, f) for f in attrs.fields(cls) if not f.name.startswith("_")]


def convert_value(field: dict[str, Any], raw: Any) -> Any:
    """The value for ``field`` from what the form sent (strings from text boxes included)."""
    name, kind = field["name"], field["kind"]
    if not field.get("editable", True):
        raise SettingRefused(f"{name} cannot be changed from the page (it is a {kind} value); use a config file")
    if raw is None and field.get("optional"):
        return None
    try:
        if kind == "bool":
            if isinstance(raw, bool):
                return raw
            if isinstance(raw, str) and raw.lower() in ("true", "false"):
                return raw.lower() == "true"
            raise ValueError
        if kind == "int":
            if isinstance(raw, bool):
                raise ValueError
            value = int(raw) if isinstance(raw, str) else raw
            if not isinstance(value, int) and not (isinstance(value, float) and value.is_integer()):
                raise ValueError
            return int(value)
        if kind == "float":
            if isinstance(raw, bool):
                raise ValueError
            return float(raw)
        if kind in ("str", "choice"):
            if kind == "choice" and raw not in field["choices"]:
                for choice in field["choices"]:
                    if str(choice) == str(raw):
                        return choice
                raise SettingRefused(f"{name} must be one of {field['choices']}, got {raw!r}")
            return raw if isinstance(raw, str) else str(raw)
    except SettingRefused:
        raise
    except (TypeError, ValueError):
        raise SettingRefused(f"{name} expects a {kind} value, got {raw!r}") from None
    return raw


async def apply_config_change(control_socket: Path, component: str, values: dict[str, Any], timeout: float = 5.0) -> dict[str, Any]:
    """Apply ``values`` to the running ``component``; returns its whole config afterwards.

    Raises :class:`SettingRefused` with the component's validator message if a value is refused
    (the component keeps its old values), or ``ConnectionError`` if it is not reachable."""
    client = AsyncRpcClient(control_socket)
    try:
        return await client.call(C.UPDATE_PARAMETERS, timeout=timeout, values=values)  # the reconfiguration service
    except RpcError as exc:
        raise SettingRefused(f"{component}: {exc}") from None
    except (RpcConnectionError, OSError) as exc:
        raise ConnectionError(f"{component} is not reachable ({exc}); is it running?") from None
    finally:
        await client.close()


async def read_config(control_socket: Path, timeout: float = 3.0) -> dict[str, Any]:
    client = AsyncRpcClient(control_socket)
    try:
        return await client.call(C.INFO, timeout=timeout)
    finally:
        await client.close()
