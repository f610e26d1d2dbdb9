"""Event conditions: ``topic.msg.<field>...`` expressions that compile to plain data.

``battery.msg.data < 20.0`` does not compare anything: ``Topic.msg`` returns a :class:`MsgPath`
that walks the message class' fields as attributes are taken (an unknown field fails here, at
definition time, naming the topic, the field and the message type), and its operators build a
:class:`Condition`. A condition is a tree of dicts, lists, strings and numbers (msgpack-encodable,
no pickle, no callables), so it can be evaluated in any process by :func:`evaluate`.

Types the checker knows (from the message field metadata, see :mod:`emos.msgs.fields`):
``message``, ``scalar`` (bool, int, float, str, or a number from an array), and ``list`` of
one of those (string lists, numpy arrays, lists of messages). Taking a field of a list of messages
maps over the list and flattens: ``multi.msg.detections.labels`` is every label of every
detection.

Evaluation is three-valued: a leaf whose topic has no fresh message (never received, or older
than the Topic's ``data_timeout``) is *unknown*; ``~unknown`` is unknown, ``False & unknown`` is
False, ``True | unknown`` is True, and an event fires only on True. So stale data can make a
condition false but never true, negated or not.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from enum import Enum
from typing import TYPE_CHECKING, Any

import attrs
import numpy as np

from emos.errors import EmosError
from emos.msgs import fields as F
from emos.msgs.registry import canonical_name

if TYPE_CHECKING:
    from emos.io.topic import Topic

# A static type: ("message", cls) | ("scalar", "bool"|"int"|"float"|"number"|"str") | ("list", elem)
TypeDesc = tuple[str, Any]


class ConditionError(EmosError, TypeError):
    """A condition that cannot be built: unknown field, unsupported comparison, bad operand."""


def _describe(t: TypeDesc) -> str:
    if t[0] == "message":
        return f"a {canonical_name(t[1])} message"
    if t[0] == "scalar":
        return {"bool": "a bool", "int": "an int", "float": "a float", "number": "a number", "str": "a str"}[t[1]]
    inner = _describe(t[1]).split(" ", 1)[1]
    return f"a list of {inner}" + ("" if inner.endswith("message") or inner.startswith("list") else "s")


def _field_type(cls: type, fld: attrs.Attribute[Any]) -> TypeDesc:
    kind = fld.metadata.get("kind")
    if kind in (F.MESSAGE, F.OPTIONAL_MESSAGE):
        return ("message", fld.metadata["cls"]())
    if kind == F.MESSAGE_LIST:
        return ("list", ("message", fld.metadata["cls"]()))
    if kind == F.STR_LIST:
        return ("list", ("scalar", "str"))
    if kind == F.ARRAY:
        return ("list", ("scalar", "number"))
    default = fld.default
    for py, name in ((bool, "bool"), (int, "int"), (float, "float"), (str, "str")):
        if isinstance(default, py):
            return ("scalar", name)
    return ("scalar", "number")


def _plain(value: Any, where: str) -> Any:
    """A static operand as msgpack-encodable data (enums by value, tuples as lists)."""
    if isinstance(value, Enum):
        value = value.value
    if isinstance(value, np.generic):
        value = value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, (list, tuple, set, frozenset, np.ndarray)):
        return [_plain(v, where) for v in (value.tolist() if isinstance(value, np.ndarray) else value)]
    from emos.io.topic import Topic

    if isinstance(value, (MsgPath, Condition, Topic)):
        raise ConditionError(f"{where}: compare with a constant, not with {type(value).__name__} {value!r}")
    raise ConditionError(f"{where}: operand must be a bool, number, str or a list of them, got {type(value).__name__} {value!r}")


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, str)


class MsgPath:
    """A path into the messages of one topic, e.g. ``odom.msg.twist.twist.linear.x``."""

    __hash__ = None  # type: ignore[assignment]  # == builds a Condition

    # Set once by __init__ (object.__setattr__: the class refuses assignment); declared here so that
    # they are not taken for path steps, which __getattr__ builds.
    _topic: Topic
    _steps: tuple[dict[str, Any], ...]
    _type: TypeDesc
    _label: str

    def __init__(self, topic: Topic, steps: tuple[dict[str, Any], ...] = (), type_: TypeDesc | None = None, label: str = "msg"):
        object.__setattr__(self, "_topic", topic)
        object.__setattr__(self, "_steps", steps)
        object.__setattr__(self, "_type", type_ if type_ is not None else ("message", topic.msg_type))
        object.__setattr__(self, "_label", label)

    # -- building the path ---------------------------------------------------------------------
    def _where(self) -> str:
        return f"event condition on topic {self._topic.name!r} ({self._topic.type_name}), {self._label}"

    def __getattr__(self, name: str) -> MsgPath:
        if name.startswith("__"):
            raise AttributeError(name)
        t = self._type
        mapped = t[0] == "list" and t[1][0] == "message"
        owner = t[1][1] if mapped else (t[1] if t[0] == "message" else None)
        if owner is None:
            raise ConditionError(f"{self._where()} is {_describe(t)}: it has no field {name!r}")
        fields = {f.name: f for f in attrs.fields(owner)}
        if name not in fields:
            raise ConditionError(
                f"{self._where()}: {canonical_name(owner)} has no field {name!r}; its fields are {', '.join(sorted(fields)) or '(none)'}"
            )
        ft = _field_type(owner, fields[name])
        flat = mapped and ft[0] == "list"
        new_t = (("list", ft[1]) if flat else ("list", ft)) if mapped else ft
        return MsgPath(self._topic, self._steps + ({"f": name, "map": mapped, "flat": flat},), new_t, f"{self._label}.{name}")

    def __setattr__(self, name: str, value: Any) -> None:
        raise ConditionError(f"{self._where()}: a condition path is read-only (did you mean ==?)")

    def __getitem__(self, index: int) -> MsgPath:
        if self._type[0] != "list" or isinstance(index, bool) or not isinstance(index, int):
            raise ConditionError(f"{self._where()} is {_describe(self._type)}: only lists take an int index, got {index!r}")
        return MsgPath(self._topic, self._steps + ({"i": index},), self._type[1], f"{self._label}[{index}]")

    def length(self) -> MsgPath:
        """The number of elements of a list field (or characters of a str field)."""
        if not (self._type[0] == "list" or self._type == ("scalar", "str")):
            raise ConditionError(f"{self._where()} is {_describe(self._type)}: length() needs a list or a str")
        return MsgPath(self._topic, self._steps + ({"len": True},), ("scalar", "int"), f"{self._label}.length()")

    def to_dict(self) -> dict[str, Any]:
        return {"topic": self._topic.name, "steps": [dict(s) for s in self._steps]}

    # -- comparisons ---------------------------------------------------------------------------
    def _leaf(self, op: str, **operands: Any) -> Condition:
        return Condition({"op": op, "path": self.to_dict(), **operands}, {self._topic.name: self._topic})

    def _scalar_kind(self) -> str | None:
        kind: str | None = self._type[1] if self._type[0] == "scalar" else None
        return kind

    def _check_value(self, op: str, value: Any, kind: str | None) -> None:
        where = f"{self._where()} {op} {value!r}"
        if kind == "str" and not isinstance(value, str):
            raise ConditionError(f"{where}: the field is a str, compare it with a str")
        if kind in ("int", "float", "number", "bool") and not (_is_number(value) or isinstance(value, bool)):
            raise ConditionError(f"{where}: the field is {_describe(self._type)}, compare it with a number")

    def _compare(self, op: str, value: Any) -> Condition:
        value = _plain(value, f"{self._where()} {op}")
        kind = self._scalar_kind()
        if op in ("==", "!="):
            if self._type[0] == "message":
                raise ConditionError(f"{self._where()} is {_describe(self._type)}: compare one of its fields instead")
            if self._type[0] == "list":
                if not isinstance(value, list):
                    raise ConditionError(f"{self._where()} {op} {value!r}: the field is {_describe(self._type)}, compare it with a list")
            elif value is not None:
                self._check_value(op, value, kind)
        else:
            if kind not in ("int", "float", "number", "str", "bool"):
                raise ConditionError(f"{self._where()} is {_describe(self._type)}: {op!r} needs a number or a str field")
            self._check_value(op, value, kind)
        return self._leaf("cmp", cmp=op, value=value)

    def __eq__(self, value: Any) -> Condition:  # type: ignore[override]
        return self._compare("==", value)

    def __ne__(self, value: Any) -> Condition:  # type: ignore[override]
        return self._compare("!=", value)

    def __lt__(self, value: Any) -> Condition:
        return self._compare("<", value)

    def __le__(self, value: Any) -> Condition:
        return self._compare("<=", value)

    def __gt__(self, value: Any) -> Condition:
        return self._compare(">", value)

    def __ge__(self, value: Any) -> Condition:
        return self._compare(">=", value)

    def _need_truthy(self, what: str) -> None:
        if self._scalar_kind() not in ("bool", "int"):
            raise ConditionError(f"{self._where()} is {_describe(self._type)}: {what} needs a bool (or int) field")

    def is_true(self) -> Condition:
        self._need_truthy("is_true()")
        return self._leaf("is_true")

    def is_false(self) -> Condition:
        self._need_truthy("is_false()")
        return self._leaf("is_false")

    def __invert__(self) -> Condition:
        self._need_truthy("~")
        return self._leaf("is_false")

    def _values(self, op: str, values: Iterable[Any], kind: str | None) -> list[Any]:
        if isinstance(values, (str, bytes)) or not isinstance(values, Iterable):
            raise ConditionError(f"{self._where()}.{op}(...): expects a list of values, got {values!r}")
        out: list[Any] = _plain(list(values), f"{self._where()}.{op}")
        for v in out:
            self._check_value(f".{op}", v, kind)
        return out

    def is_in(self, values: Iterable[Any]) -> Condition:
        if self._type[0] != "scalar":
            raise ConditionError(f"{self._where()} is {_describe(self._type)}: is_in() needs a single value; for lists use contains_any()")
        return self._leaf("in", values=self._values("is_in", values, self._scalar_kind()))

    def not_in(self, values: Iterable[Any]) -> Condition:
        if self._type[0] != "scalar":
            raise ConditionError(f"{self._where()} is {_describe(self._type)}: not_in() needs a single value; for lists use not_contains_any()")
        return self._leaf("not_in", values=self._values("not_in", values, self._scalar_kind()))

    def _elem_kind(self, op: str) -> str | None:
        if self._type == ("scalar", "str"):
            return "str"
        if self._type[0] == "list" and self._type[1][0] == "scalar":
            kind: str = self._type[1][1]
            return kind
        raise ConditionError(f"{self._where()} is {_describe(self._type)}: {op}() needs a list of values or a str")

    def contains(self, value: Any) -> Condition:
        kind = self._elem_kind("contains")
        value = _plain(value, f"{self._where()}.contains")
        self._check_value(".contains", value, kind)
        return self._leaf("contains", value=value)

    def contains_any(self, values: Iterable[Any]) -> Condition:
        return self._leaf("contains_any", values=self._values("contains_any", values, self._elem_kind("contains_any")))

    def contains_all(self, values: Iterable[Any]) -> Condition:
        return self._leaf("contains_all", values=self._values("contains_all", values, self._elem_kind("contains_all")))

    def not_contains_any(self, values: Iterable[Any]) -> Condition:
        return self._leaf("not_contains_any", values=self._values("not_contains_any", values, self._elem_kind("not_contains_any")))

    def __bool__(self) -> bool:
        raise ConditionError(f"{self._where()}: a condition path has no truth value; use .is_true(), comparisons, & | ~ (not and/or/not)")

    def __repr__(self) -> str:
        return f"MsgPath({self._topic.name}:{self._label})"


def new_message(topic: Topic) -> Condition:
    """True when the message being evaluated arrived on ``topic`` (a bare Topic in a condition)."""
    return Condition({"op": "new_msg", "topic": topic.name}, {topic.name: topic})


def as_condition(value: Any, where: str) -> Condition:
    from emos.io.topic import Topic

    if isinstance(value, Condition):
        return value
    if isinstance(value, Topic):
        return new_message(value)
    if isinstance(value, MsgPath):
        raise ConditionError(f"{where}: {value!r} is a value, not a condition; compare it or use .is_true()")
    raise ConditionError(f"{where}: operands must be conditions or Topics, got {type(value).__name__} {value!r}")


class Condition:
    """A boolean expression over the latest messages of one or more topics (plain-data tree)."""

    __hash__ = object.__hash__

    def __init__(self, tree: dict[str, Any], topics: Mapping[str, Topic]):
        self.tree = tree
        self.topics: dict[str, Topic] = dict(topics)

    def _combine(self, op: str, other: Any) -> Condition:
        other = as_condition(other, f"condition {op}")
        args: list[dict[str, Any]] = []
        for c in (self, other):
            args.extend(c.tree["args"] if c.tree["op"] == op else [c.tree])
        return Condition({"op": op, "args": args}, {**self.topics, **other.topics})

    def __and__(self, other: Any) -> Condition:
        return self._combine("and", other)

    def __rand__(self, other: Any) -> Condition:
        return as_condition(other, "condition and")._combine("and", self)

    def __or__(self, other: Any) -> Condition:
        return self._combine("or", other)

    def __ror__(self, other: Any) -> Condition:
        return as_condition(other, "condition or")._combine("or", self)

    def __invert__(self) -> Condition:
        if self.tree["op"] == "not":
            return Condition(self.tree["arg"], self.topics)
        return Condition({"op": "not", "arg": self.tree}, self.topics)

    def __bool__(self) -> bool:
        raise ConditionError("a condition has no truth value at definition time; combine conditions with & | ~ (not and/or/not)")

    def to_dict(self) -> dict[str, Any]:
        """Plain data: the tree plus, per topic, what evaluating it needs (type and data_timeout)."""
        return {"tree": self.tree, "topics": {n: {"msg_type": t.type_name, "data_timeout": t.data_timeout} for n, t in self.topics.items()}}

    def __repr__(self) -> str:
        return f"Condition({render(self.tree)})"


# ============================================================================ evaluation
_MISSING = object()


def resolve_path(path: Mapping[str, Any], msg: Any) -> Any:
    """The value a :class:`MsgPath` (as dict) names in ``msg``; ``_MISSING`` if an index is out of range."""
    value = msg
    for step in path["steps"]:
        if "f" in step:
            name = step["f"]
            if step["map"]:
                if step["flat"]:
                    value = [x for v in value for x in _as_list(getattr(v, name))]
                else:
                    value = [getattr(v, name) for v in value]
            else:
                value = None if value is None else getattr(value, name)
        elif "i" in step:
            seq = _as_list(value)
            try:
                value = seq[step["i"]]
            except (IndexError, TypeError):
                return _MISSING
        else:
            value = len(_as_list(value)) if not isinstance(value, str) else len(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _as_list(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    return [] if value is None else value


_CMP: dict[str, Callable[[Any, Any], bool]] = {
    "==": lambda a, b: a == b, "!=": lambda a, b: a != b, "<": lambda a, b: a < b,
    "<=": lambda a, b: a <= b, ">": lambda a, b: a > b, ">=": lambda a, b: a >= b,
}


def _leaf(tree: Mapping[str, Any], value: Any) -> bool | None:
    op = tree["op"]
    if op == "cmp":
        return bool(_CMP[tree["cmp"]](value, tree["value"]))
    if op == "is_true":
        return bool(value)
    if op == "is_false":
        return not value
    if op == "in":
        return value in tree["values"]
    if op == "not_in":
        return value not in tree["values"]
    if op == "contains":
        return tree["value"] in value
    if op == "contains_any":
        return any(v in value for v in tree["values"])
    if op == "contains_all":
        return all(v in value for v in tree["values"])
    if op == "not_contains_any":
        return not any(v in value for v in tree["values"])
    raise ValueError(f"unknown condition operator {op!r}")


def evaluate(tree: Mapping[str, Any], fresh: Callable[[str], Any], trigger_topic: str | None = None) -> bool | None:
    """Three-valued evaluation: True, False, or None (unknown: an input is missing or stale).

    ``fresh(topic_name)`` returns the latest *fresh* message of a topic or None.
    ``trigger_topic`` is the topic whose message is being evaluated (for bare-Topic leaves).
    """
    op = tree["op"]
    if op == "and":
        unknown = False
        for arg in tree["args"]:
            r = evaluate(arg, fresh, trigger_topic)
            if r is False:
                return False
            unknown |= r is None
        return None if unknown else True
    if op == "or":
        unknown = False
        for arg in tree["args"]:
            r = evaluate(arg, fresh, trigger_topic)
            if r is True:
                return True
            unknown |= r is None
        return None if unknown else False
    if op == "not":
        r = evaluate(tree["arg"], fresh, trigger_topic)
        return None if r is None else not r
    if op == "new_msg":
        if trigger_topic == tree["topic"]:
            return True
        return False if fresh(tree["topic"]) is not None else None
    msg = fresh(tree["path"]["topic"])
    if msg is None:
        return None
    value = resolve_path(tree["path"], msg)
    if value is _MISSING:
        return None
    try:
        return _leaf(tree, value)
    except TypeError:  # e.g. None compared with a number: an optional field that is unset
        return None


def topics_of(tree: Mapping[str, Any]) -> set[str]:
    op = tree["op"]
    if op in ("and", "or"):
        return set().union(*(topics_of(a) for a in tree["args"]))
    if op == "not":
        return topics_of(tree["arg"])
    if op == "new_msg":
        return {tree["topic"]}
    return {tree["path"]["topic"]}


def render(tree: Mapping[str, Any]) -> str:
    """A readable form of a condition tree, for logs."""
    op = tree["op"]
    if op in ("and", "or"):
        return "(" + f" {'&' if op == 'and' else '|'} ".join(render(a) for a in tree["args"]) + ")"
    if op == "not":
        return f"~{render(tree['arg'])}"
    if op == "new_msg":
        return f"<new message on {tree['topic']}>"
    path = tree["path"]["topic"] + ":msg" + "".join(
        f".{s['f']}" if "f" in s else (f"[{s['i']}]" if "i" in s else ".length()") for s in tree["path"]["steps"]
    )
    if op == "cmp":
        return f"{path} {tree['cmp']} {tree['value']!r}"
    if op in ("is_true", "is_false"):
        return f"{path}.{op}()"
    arg = tree.get("values", tree.get("value"))
    return f"{path}.{ {'in': 'is_in'}.get(op, op)}({arg!r})"


# ============================================================================ compiled evaluation
Compiled = Callable[[Callable[[str], Any], "str | None"], "bool | None"]


def compile_condition(tree: Mapping[str, Any]) -> Compiled:
    """The condition as one generated function (see :mod:`emos.events.compiled`); same results
    as :func:`evaluate`, about ten times faster per armed event."""
    from emos.events.compiled import compile_tree

    return compile_tree(tree)
