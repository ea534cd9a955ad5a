"""The configuration schema: a key's type, default, doc and limits, derived from a settings dataclass, and the
checker that validates a TOML table against it with one-line errors.

Shared by the appliance configuration (``service.config.appliance``) and the recipe files
(``service.parts.recipes``); the tables a publisher (``PublisherTable``) and a sensor (``SensorTable``) declare.
It imports no settings module: every one imports it.
"""

from __future__ import annotations

import collections.abc
import dataclasses
import difflib
import math
import typing
from dataclasses import dataclass, field
from types import UnionType
from typing import Any, Callable, Mapping, Union

from measurement.effects import EFFECTS
from service.errors import ConfigError
from service.settings.checks import Check

#: the default of a key that must be given
REQUIRED = object()


@dataclass(frozen=True)
class Key:
    kind: str  # str | int | float | bool | path | strlist | table | effects | pinlike | videodevice
    default: Any = None
    doc: str = ""
    choices: tuple[Any, ...] | None = None
    min: float | None = None
    max: float | None = None
    min_open: bool = False  # min is exclusive

    def expected(self) -> str:
        if self.choices:
            return "one of " + ", ".join(repr(c) for c in self.choices)
        names = {"str": "a string", "path": "a path (string)", "int": "an integer", "float": "a number",
                 "bool": "true or false", "strlist": "a list of strings", "table": "a table",
                 "effects": "a table of effect = { parameter = value }",
                 "pinlike": "a BCM pin number or a name like 'GPIO17'",
                 "videodevice": "a video device path like '/dev/video0' or a device index >= 0"}
        text = names[self.kind]
        if self.min is not None and self.max is not None:
            text += f" in {'(' if self.min_open else '['}{self.min:g}, {self.max:g}]"
        elif self.min is not None:
            text += f" {'>' if self.min_open else '>='} {self.min:g}"
        return text


def kind_of(hint: Any) -> str:
    """The schema kind of a settings field's type (``int | None`` → "int", ``int | str`` → "pinlike")."""
    args = [a for a in typing.get_args(hint) if a is not type(None)] if typing.get_origin(hint) in (Union, UnionType) \
        else [hint]
    if set(args) == {int, str}:
        return "pinlike"
    (t,) = args
    origin = typing.get_origin(t) or t
    if origin in (tuple, list):
        return "strlist"
    if origin in (dict, Mapping, collections.abc.Mapping) or dataclasses.is_dataclass(origin):
        return "table"
    return {bool: "bool", int: "int", float: "float", str: "str"}[origin]


def default_of(cls: type, name: str) -> Any:
    """The default of the field ``name`` of the settings dataclass ``cls`` (REQUIRED when it has none): what a
    command-line option that stands for that setting defaults to, so the two never disagree."""
    f = {f.name: f for f in dataclasses.fields(cls)}[name]
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return REQUIRED


def schema(cls: type, keys: Mapping[str, Mapping[str, Any]], *, extra: Mapping[str, Key] | None = None,
            defaults: Mapping[str, Any] | None = None) -> dict[str, Key]:
    """The table of ``cls``: one key per field named in ``keys`` (the field's doc and limits), in the field order.

    The key's type and default come from the field (a field without default is required);
    ``keys[name]`` adds the doc, choices, min/max and, where the type alone does not say it, the
    kind ("path", "effects", "videodevice"). Every key of ``keys`` must be a field of ``cls``.
    """
    hints = typing.get_type_hints(cls)
    fields = [f.name for f in dataclasses.fields(cls)]
    missing = set(keys) - set(fields)
    assert not missing, f"{cls.__name__} has no field(s) {sorted(missing)}"
    out: dict[str, Key] = dict(extra or {})
    for name in fields:
        if name not in keys:
            continue
        default = defaults[name] if defaults and name in defaults else default_of(cls, name)
        spec = dict(keys[name])
        out[name] = Key(spec.pop("kind", None) or kind_of(hints[name]), default, **spec)
    return out


def doc(text: str = "", **limits: Any) -> dict[str, Any]:
    """A key's doc and limits, for ``schema``."""
    return {"doc": text, **limits}


#: a publisher's own checks of its table: ``check(values, fail)`` may adjust the checked values in place and
#: raises ``fail(key, message)`` (a ConfigError naming the file, the table and the key) for a bad combination
TableCheck = Callable[[dict[str, Any], Callable[[str, str], ConfigError]], None]


@dataclass(frozen=True)
class PublisherTable:
    """A publisher's configuration table, declared in its settings module (``TABLE``) and found through the
    publishers' registry (``service.publish.registry``): the settings dataclass, each key's doc and limits, the
    doc of its ``enabled`` key, whether it is on without the table, its own checks (of the values as the file is
    read, and of the environment before the daemon starts), the descriptors its clients hold and whom to call.

    Keys of kind "path" are resolved relative to the configuration file before ``check`` sees them.
    """

    settings: type
    keys: Mapping[str, Mapping[str, Any]]
    #: the doc of the table's ``enabled`` key (default true)
    enabled: str
    #: on with its defaults when the file has no such table (else off unless the table is given)
    on_without_table: bool = False
    check: TableCheck | None = None
    #: what `moi run --check` finds of its settings before the daemon starts (ports, files, exposure)
    start_checks: Callable[[Any], list[Check]] | None = None
    #: the descriptors its clients may hold at once, by the name `moi run --check` gives it (``{"Modbus": 16}``;
    #: none: it serves no connections)
    descriptors: Callable[[Any], dict[str, int]] | None = None
    #: whom the appliance's doors say to call (a calibration that refuses Measure), None: not said here
    contact: Callable[[Any], str | None] | None = None

    def schema(self) -> dict[str, Key]:
        return schema(self.settings, self.keys, extra={"enabled": Key("bool", True, self.enabled)})


#: ``fail(key, message)``: the ConfigError naming the configuration file, the table and the key (None: the table)
SensorFail = Callable[[str | None, str], ConfigError]


@dataclass(frozen=True)
class SensorTable:
    """A hardware sensor's settings table ``[hardware.<name>]``, declared in its sensor module (``TABLE`` of its
    ``service.devices.sensors.port.SensorKind``) and found through the sensors' registry: the configuration builds
    the table's schema, its key in ``[hardware]``, the reference (docs/service.md) and the parse from it, and names
    no sensor.

    The table is optional in the file; with ``[hardware] sensor = "<name>"`` it is required, and it is parsed
    (``parse``) only then: ``HardwareSettings.sensors[<name>]`` holds what ``parse`` returns.
    """

    #: the sensor in a few words, for the doc of ``[hardware] sensor`` ("the Modbus encoder")
    what: str
    #: the doc of its key in ``[hardware]``: what the table holds
    doc: str
    #: what the table must give, said when ``sensor = "<name>"`` has no table ("port, device id, ...")
    needs: str
    #: the settings dataclass and each key's doc and limits, as a publisher's table (``service.settings.schema.schema``;
    #: keys of kind "path" are resolved relative to the configuration file before ``parse`` sees them);
    #: None: the keys are the driver's own, handed to ``parse`` as written for the driver to check
    settings: type | None = None
    keys: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    #: the sensor's settings from its table's values (``SensorFail`` for a bad one); None: ``settings(**values)``
    parse: Callable[[dict[str, Any], SensorFail], Any] | None = None

    def schema(self) -> dict[str, Key] | None:
        """The table's keys (None: the driver's own, not declared here)."""
        return None if self.settings is None else schema(self.settings, self.keys)

    def read(self, values: dict[str, Any], fail: SensorFail) -> Any:
        """The sensor's settings from the checked values of its table."""
        if self.parse is not None:
            return self.parse(values, fail)
        assert self.settings is not None, "a table without a settings dataclass parses its own values"
        return self.settings(**values)


#: what a kind's reader returns for a value of the wrong type
_BAD = object()


def _number(v: Any) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float))


def _video_device(v: Any) -> Any:
    if isinstance(v, bool) or not isinstance(v, (int, str)) or (isinstance(v, int) and v < 0) or v == "":
        return _BAD
    return int(v) if isinstance(v, str) and v.isdigit() else v  # "0": the index, not a file named 0


#: each kind's reader (but "effects", which says what is wrong in it): the value as the settings hold it, or _BAD
_KINDS: dict[str, Callable[[Any], Any]] = {
    "str": lambda v: v if isinstance(v, str) else _BAD,
    "path": lambda v: v if isinstance(v, str) and v else _BAD,
    # checked with the rest of its table by the driver's settings (drivers.settings.check_pin)
    "pinlike": lambda v: v,
    "videodevice": _video_device,
    "bool": lambda v: v if isinstance(v, bool) else _BAD,
    "int": lambda v: v if isinstance(v, int) and not isinstance(v, bool) else _BAD,
    "float": lambda v: float(v) if _number(v) and math.isfinite(v) else _BAD,
    "strlist": lambda v: tuple(v) if isinstance(v, list) and all(isinstance(x, str) for x in v) else _BAD,
    "table": lambda v: dict(v) if isinstance(v, Mapping) else _BAD,
}


def _within(v: float, spec: Key) -> bool:
    """Whether the number ``v`` lies within the key's limits."""
    if spec.min is not None and (v < spec.min or (spec.min_open and v == spec.min)):
        return False
    return spec.max is None or v <= spec.max


class Checker:
    """Checks a document's tables against their schema; every error is a ConfigError naming the file, the table and the key."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, table: str, key: str | None, message: str) -> ConfigError:
        where = f"[{table}]" + (f" {key}" if key else "")
        return ConfigError(f"{self.source}: {where}: {message}")

    def table(self, name: str, doc: Any, schema: Mapping[str, Key]) -> dict[str, Any]:
        if not isinstance(doc, Mapping):
            raise self.fail(name, None, f"expected a table, got {type(doc).__name__} {doc!r}")
        unknown = [k for k in doc if k not in schema]
        if unknown:
            k = unknown[0]
            close = difflib.get_close_matches(k, list(schema), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else f"; expected one of: {', '.join(schema)}"
            raise self.fail(name, None, f"unknown key {k!r}{hint}")
        out: dict[str, Any] = {}
        for key, spec in schema.items():
            if key not in doc:
                if spec.default is REQUIRED:
                    raise self.fail(name, key, f"missing; expected {spec.expected()}"
                                    + (f" ({spec.doc})" if spec.doc else ""))
                out[key] = spec.default
                continue
            out[key] = self.value(name, key, doc[key], spec)
        return out

    def value(self, table: str, key: str, v: Any, spec: Key) -> Any:
        bad = self.fail(table, key, f"expected {spec.expected()}, got {v!r}")
        if spec.kind == "effects":
            v = self.effects(table, key, v)
        else:
            v = _KINDS[spec.kind](v)
            if v is _BAD:
                raise bad
        if spec.choices is not None and v not in spec.choices:
            raise bad
        if spec.kind in ("int", "float") and not _within(v, spec):
            raise bad
        return v

    def effects(self, table: str, key: str, v: Any) -> dict[str, dict[str, float]]:
        if not isinstance(v, Mapping):
            raise self.fail(table, key, f"expected a table of effect = {{ parameter = value }}, got {v!r}")
        out: dict[str, dict[str, float]] = {}
        for name, params in v.items():
            if name not in EFFECTS:
                raise self.fail(table, key, f"unknown effect {name!r}; expected one of {', '.join(EFFECTS)}")
            if not isinstance(params, Mapping) or not params:
                raise self.fail(table, key, f"{name}: expected {{ parameter = value }}, e.g. viscous = {{ c = 1.5e-4 }}")
            vals: dict[str, float] = {}
            for p, x in params.items():
                if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                    raise self.fail(table, key, f"{name}.{p}: expected a number, got {x!r}")
                vals[str(p)] = float(x)
            out[str(name)] = vals
        return out
