"""The appliance configuration: one TOML file, validated with one-line errors.

Every table and key is declared once: the appliance's own tables below (their settings dataclasses and
``Config``, which the devices and the publishers read, in ``service.settings.config``), each publisher's table
in its settings module (``TABLE``), found through the publishers' registry (``service.publish.registry``);
``SCHEMA`` holds them all.
An unknown key, a wrong type, a value out of range or a missing hardware
setting raises ``ConfigError`` naming the file, the table, the key and what
was expected.
docs/service.md shows the whole file; examples/appliance.toml is a
commented example.

Without a ``[hardware]`` table (or with ``--sim``) the appliance runs on the
simulated rig described by ``[simulation]``.

The angle sensor (``[hardware] sensor``) brings its own table, ``[hardware.<sensor>]``: its keys, docs and parse
are its sensor module's (``SensorKind.TABLE``, found through the sensors' registry,
``service.settings.sensor_registry``), so this module names no sensor. Files a sensor's table names (the camera
file) are read and checked here, so a missing or malformed one is a configuration error naming both files.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import os
from pathlib import Path
from typing import Any, Mapping, overload

from drivers.errors import DriverConfigError
from drivers.settings import ABSOLUTE_MAX_ON_TIME, INDICATOR_KINDS, ButtonSettings, IndicatorSettings, SolenoidSettings
from firmware_host import SequencerConfig
from measurement import Options, Pendulum, Rig
from measurement.effects import EFFECTS
from measurement.errors import InvalidInput
from service.errors import ConfigError
from service.names import name_problem
from service.parts.recipes import RecipeBook
from service.publish import registry
from service.settings import sensor_registry
from service.settings.config import (
    MAX_TIME_SCALE,
    Config,
    DeviceSettings,
    HardwareSettings,
    RecipeSettings,
    SimulationSettings,
)
from service.settings.defaults import DEMO_RIG, MAX_ENCODER_TIME_SCALE
from service.settings.schema import REQUIRED, Checker, Key, PublisherTable, SensorTable
from service.settings.schema import doc as _doc
from service.settings.schema import schema as _schema
from service.sources.files import read_rig, read_toml

#: the rig simulated when ``[device] rig`` is not given (the demo rig of `moi demo`)
DEFAULT_SIM_RIG = DEMO_RIG


def _sequencer_keys() -> dict[str, dict[str, Any]]:
    docs = {
        "pre_trigger": "capture before the release, s", "release_pulse": "solenoid pulse asked for, s",
        "capture_duration": "capture after the release (at most), s",
        "decay_threshold": "end the capture once the half peak-to-peak angle is below this, rad (0: off)",
        "decay_window": "window of the decay test, s", "min_capture": "no decay test before this, s",
        "sample_timeout": "no sample for this long → FAULT, s", "identify_timeout": "identification limit, s",
        "min_samples": "fewer samples → FAULT",
    }
    # identify_in_worker is not a key: the daemon always identifies in a worker (poll must stay responsive)
    return {f.name: _doc(docs[f.name], min=0) for f in dataclasses.fields(SequencerConfig)
            if f.name != "identify_in_worker"}


_PIN = _doc("BCM pin number or gpiozero pin name")

#: the appliance's own tables up to [hardware]; the sensors' tables, the rest (``_AFTER_SENSORS``) and the
#: publishers' follow (``tables``)
_APPLIANCE: dict[str, dict[str, Key]] = {
    "device": _schema(DeviceSettings, {
        "id": _doc("device id: names the MQTT topics and Home Assistant entities"),
        "state_dir": _doc("result store directory (default $STATE_DIRECTORY, else ./moi-state)", kind="path"),
        "rig": _doc("rig TOML file (required with [hardware]; relative paths are relative to this file)", kind="path"),
        "log_level": _doc("logging level", choices=("debug", "info", "warning", "error")),
        "store_trace": _doc("keep the raw trace of every measurement in the store"),
        "require_calibration": _doc("refuse Measure on a rig without a calibration record (default: measure, and "
                                    "say \"rig not calibrated\" on every page and in moi run --check)"),
    }),
    "sequencer": _schema(SequencerConfig, _sequencer_keys()),
    "identification": _schema(Options, {
        "discover": _doc("run the discovery loop"),
        "candidates": _doc("effects the loop may add (default: all)"),
        "min_swings": _doc("fewer full swings is an input error", min=0),
        "bic_margin": _doc("an added effect must lower BIC by more than this", min=0),
    }),
    # its sensor key and one key per sensor's table are added from the sensors' registry (``_hardware``)
    "hardware": _schema(HardwareSettings, {
        "gpio_backend": _doc("gpiozero pin factory (lgpio on a Pi, mock for tests; default: gpiozero's)"),
        "sensor": _doc(""),
        "solenoid": _doc("[hardware.solenoid] pin, active_high, max_on_time"),
        "button": _doc("[hardware.button] pin, pull_up, bounce_time"),
        "indicator": _doc("[hardware.indicator] pin, kind, active_high"),
    }),
    # the GPIO tables: keys and defaults of the drivers' settings, which also check the values
    "hardware.solenoid": _schema(SolenoidSettings, {
        "pin": _PIN, "active_high": _doc("a high level energises the coil"),
        "max_on_time": _doc(f"hard limit of one pulse, s (at most {ABSOLUTE_MAX_ON_TIME:g})"),
    }),
    "hardware.button": _schema(ButtonSettings, {
        "pin": _PIN, "pull_up": _doc("pressed pulls the line low"),
        "bounce_time": _doc("contact bounce suppression, s (at most 1)"),
    }),
    "hardware.indicator": _schema(IndicatorSettings, {
        "pin": _PIN, "kind": _doc("", choices=INDICATOR_KINDS), "active_high": _doc(""),
    }),
}
_AFTER_SENSORS: dict[str, dict[str, Key]] = {
    "simulation": _schema(SimulationSettings, {
        "inertia": _doc("true J of the simulated part, kg·m²", min=0, min_open=True),
        "effects": _doc("true damping: effect = { parameter = value }", kind="effects"),
        "theta0": _doc("release angle, rad", min=0, max=3.0, min_open=True),
        "rate": _doc("sample rate of the direct sensor, and the rate the simulated encoder is read at (at most: "
                     "the link answers some 500–1500 reads per wall-clock second), Hz of simulated time",
                     min=0, max=10000, min_open=True),
        "noise": _doc("angle noise σ, rad", min=0),
        "bits": _doc("encoder resolution, bits per turn (0: none)", min=0, max=32),
        "time_scale": _doc(f"simulated seconds per wall-clock second (at most {MAX_ENCODER_TIME_SCALE:g} with "
                           f"sensor = \"encoder\")", min=0, max=MAX_TIME_SCALE, min_open=True),
        "seed": _doc("noise seed (default: random)"),
        "sensor": _doc("\"encoder\": a simulated Modbus RTU encoder on a loopback socket read by the real encoder "
                       "client; \"direct\": an in-process sensor sampling at rate (faster); \"camera\": a mock camera "
                       "rendering the marker, read by the real camera sensor (keep time_scale = 1: frames are "
                       "rendered in real time)", choices=sensor_registry.names()),
        "latency": _doc("simulated encoder reply latency, s of real time", min=0, max=1),
        "camera": _doc("camera file of the simulated camera (sensor = \"camera\"; default: the demo camera, 640×480 px "
                       "at 100 frames/s, fx = 600 px, marker radius 0.10 m at 0.25 m); relative to this file",
                       kind="path"),
        "camera_yaw_deg": _doc("yaw of the simulated camera, degrees, within ±20 (estimated and corrected by the "
                               "sensor)", min=-20, max=20),
        "drop_rate": _doc("fraction of encoder replies (or camera frames) lost", min=0, max=1),
        "crc_rate": _doc("fraction of encoder replies with a corrupted CRC", min=0, max=1),
        "glitch_rate": _doc("fraction of encoder replies whose position is off by 1/128 turn although the CRC is "
                            "right (a glitch the identification must catch)", min=0, max=1),
    }),
    "recipes": _schema(RecipeSettings, {
        "directory": _doc("directory of the recipe files, one TOML file per part type (docs/service.md, Recipes); "
                          "relative to this file", kind="path"),
        "active": _doc("recipe active at start (name or number); the PLC (register recipe_select) or MQTT "
                       "(cmd/recipe) may change it"),
    }),
}



def publisher_tables() -> dict[str, PublisherTable]:
    """The publishers' tables, by name, in the registry's order (``service.publish.registry``)."""
    return _publisher_tables(registry.PUBLISHERS)


@functools.cache
def _publisher_tables(entries: tuple[registry.PublisherEntry, ...]) -> dict[str, PublisherTable]:
    return {e.name: e.table() for e in entries}


def whom_to_call(config: Config) -> str | None:
    """Whom the appliance's doors say to call (a calibration that refuses Measure): the first enabled publisher
    that names someone (its table's ``contact``), None when none does."""
    for name, table in publisher_tables().items():
        settings = config.publishers.get(name)
        if table.contact is not None and settings is not None and (who := table.contact(settings)):
            return who
    return None


def sensor_tables() -> dict[str, SensorTable]:
    """The hardware sensors' tables ``[hardware.<name>]``, by name, in the registry's order."""
    return _sensor_tables(sensor_registry.SENSORS)


@functools.cache
def _sensor_tables(entries: tuple[sensor_registry.SensorEntry, ...]) -> dict[str, SensorTable]:
    return {e.name: table for e in entries if e.hardware and (table := e.table()) is not None}


def _hardware(own: Mapping[str, SensorTable]) -> dict[str, Key]:
    """[hardware]: its own keys, the sensor key naming every hardware sensor, one key per sensor's table."""
    said = " or ".join(f"{t.what} ([hardware.{name}])" for name, t in own.items())
    keys = dict(_APPLIANCE["hardware"])
    keys["sensor"] = dataclasses.replace(keys["sensor"], doc=f"angle sensor: {said}",
                                         choices=sensor_registry.names(hardware=True))
    return {**keys, **{name: Key("table", None, t.doc) for name, t in own.items()}}


def tables() -> dict[str, dict[str, Key]]:
    """Every table of the file and its keys: the appliance's, each registered sensor's, each registered publisher's."""
    return _tables(registry.PUBLISHERS, sensor_registry.SENSORS)


@functools.cache
def _tables(entries: tuple[registry.PublisherEntry, ...],
            sensor_entries: tuple[sensor_registry.SensorEntry, ...]) -> dict[str, dict[str, Key]]:
    own = _sensor_tables(sensor_entries)
    declared = {f"hardware.{name}": keys for name, t in own.items() if (keys := t.schema()) is not None}
    return {**_APPLIANCE, "hardware": _hardware(own), **declared, **_AFTER_SENSORS,
            **{name: t.schema() for name, t in _publisher_tables(entries).items()}}


def top_tables() -> tuple[str, ...]:
    """The tables a file may have at its top level (the others are sub-tables, like [hardware.solenoid])."""
    return tuple(t for t in tables() if "." not in t)


#: every table of the file and its keys (the publishers registered when the configuration is imported)
SCHEMA: dict[str, dict[str, Key]] = tables()


@overload
def _resolve(base: Path, p: str) -> str: ...
@overload
def _resolve(base: Path, p: str | None) -> str | None: ...
def _resolve(base: Path, p: str | None) -> str | None:
    if p is None:
        return None
    q = Path(os.path.expanduser(p))
    return str(q if q.is_absolute() else (base / q))


def default_state_dir(environ: Mapping[str, str] | None = None) -> Path:
    """$STATE_DIRECTORY (set by systemd's StateDirectory=), else ./moi-state."""
    env = os.environ if environ is None else environ
    sd = env.get("STATE_DIRECTORY")
    if sd:
        return Path(sd.split(":")[0])
    return Path("moi-state")


def load_config(path: str | os.PathLike | None, *, sim: bool = False, state_dir: str | None = None,
                environ: Mapping[str, str] | None = None) -> Config:
    """Read and validate the configuration. ``path`` None: all defaults (simulated rig).

    sim: force the simulated rig even when [hardware] is configured (the
    hardware table is still validated). state_dir: overrides [device] state_dir.
    """
    if path is None:
        doc: dict[str, Any] = {}
        source = "<defaults>"
        base = Path.cwd()
    else:
        doc = read_toml(path, "config file")
        source = str(path)
        base = Path(path).resolve().parent
    return parse_config(doc, source=source, base=base, sim=sim, state_dir=state_dir, environ=environ)


def _check_top_tables(doc: Mapping[str, Any], source: str) -> None:
    """Every table at the file's top level is one of ours (else the one it was likely meant to be)."""
    top = top_tables()
    unknown = [t for t in doc if t not in top]
    if unknown:
        t = unknown[0]
        close = difflib.get_close_matches(t, top, n=1)
        hint = f" (did you mean [{close[0]}]?)" if close else f"; expected tables: {', '.join(f'[{x}]' for x in top)}"
        kind = "table" if isinstance(doc[t], Mapping) else "top-level key"
        raise ConfigError(f"{source}: unknown {kind} {t!r}{hint}")


def parse_config(doc: Mapping[str, Any], *, source: str = "<config>", base: Path | None = None, sim: bool = False,
                 state_dir: str | None = None, environ: Mapping[str, str] | None = None) -> Config:
    """The configuration of the file's tables ``doc`` (paths relative to ``base``), each table checked in the
    file's reading order: the first problem is the one said."""
    c = Checker(source)
    base = base or Path.cwd()
    _check_top_tables(doc, source)
    dev = _device_table_values(c, doc)
    sequencer, options = _sequencer(c, doc), _identification(c, doc)
    hardware = _hardware_settings(c, base, doc["hardware"]) if "hardware" in doc else None
    simulation = _simulation_settings(c, base, doc.get("simulation", {}))
    simulated = sim or hardware is None
    rig_path = _resolve(base, dev["rig"])
    rig = _rig(c, rig_path, simulated)
    if simulated:
        _check_simulated_rig(c, rig, simulation)
    rc = c.table("recipes", doc.get("recipes", {}), SCHEMA["recipes"])
    book = _recipes(c, _resolve(base, rc["directory"]), rc["active"], rig)
    publishers = {name: _publisher(c, base, name, table, doc) for name, table in publisher_tables().items()}
    sd = state_dir or _resolve(base, dev["state_dir"])
    return Config(
        source=source, device_id=dev["id"],
        state_dir=Path(sd) if sd else default_state_dir(environ),
        log_level=dev["log_level"], store_trace=dev["store_trace"],
        rig=rig, rig_path=rig_path, simulated=simulated, simulation=simulation, hardware=hardware,
        sequencer=sequencer, identification=options, publishers=publishers,
        recipes=book, active_recipe=rc["active"], require_calibration=dev["require_calibration"],
    )


def _device_table_values(c: Checker, doc: Mapping[str, Any]) -> dict[str, Any]:
    """[device], its id a name every surface can carry."""
    dev = c.table("device", doc.get("device", {}), SCHEMA["device"])
    if (problem := name_problem("device_id", dev["id"])) is not None:
        raise c.fail("device", "id", problem)
    return dev


def _sequencer(c: Checker, doc: Mapping[str, Any]) -> SequencerConfig:
    values = c.table("sequencer", doc.get("sequencer", {}), SCHEMA["sequencer"])
    try:
        return SequencerConfig(**values, identify_in_worker=True)
    except InvalidInput as exc:
        raise ConfigError(f"{c.source}: [sequencer]: {exc}") from None


def _identification(c: Checker, doc: Mapping[str, Any]) -> Options:
    ident = c.table("identification", doc.get("identification", {}), SCHEMA["identification"])
    for name in ident["candidates"] or ():
        if name not in EFFECTS:
            raise c.fail("identification", "candidates", f"unknown effect {name!r}; expected names from {', '.join(EFFECTS)}")
    return Options(**ident)


def _rig(c: Checker, rig_path: str | None, simulated: bool) -> Rig:
    """The rig file of [device] rig; the demo rig when simulated without one."""
    if rig_path is not None:
        try:
            return read_rig(rig_path)
        except InvalidInput as exc:
            raise ConfigError(f"{c.source}: [device] rig: {exc}") from None
    if not simulated:
        raise c.fail("device", "rig", "missing: a rig file (kind, stiffness or mass/com_distance, declared effects) "
                     "is required with [hardware]")
    return DEMO_RIG


def _check_simulated_rig(c: Checker, rig: Rig, simulation: SimulationSettings) -> None:
    """The simulated part's effects resolved on this rig, their parameter names checked."""
    try:
        Pendulum(rig, simulation.inertia, simulation.effects).parameter_vector(simulation.theta0)
    except InvalidInput as exc:
        raise ConfigError(f"{c.source}: [simulation]: {exc}") from None


def _recipes(c: Checker, directory: str | None, active: str | None, rig: Rig) -> RecipeBook:
    """Every recipe of [recipes] directory (``RecipeBook``; a RecipeError is one line naming the recipe file), the
    active one among them, each measuring a quantity the rig can give."""
    book = RecipeBook.load(directory)
    if active is not None:
        try:
            book.find(active)
        except ConfigError as exc:
            raise c.fail("recipes", "active", str(exc)) from None
    for r in book.recipes:
        r.check_rig(rig)
    return book


def _publisher(c: Checker, base: Path, name: str, table: PublisherTable, doc: Mapping[str, Any]) -> Any:
    """A publisher's settings from its table (None: off), checked by the publisher's own checks."""
    if name not in doc and not table.on_without_table:
        return None
    schema = tables()[name]
    values = c.table(name, doc.get(name, {}), schema)
    if not values.pop("enabled"):
        return None
    for key, spec in schema.items():
        if spec.kind == "path":
            values[key] = _resolve(base, values[key])
    if table.check is not None:
        table.check(values, lambda key, message: c.fail(name, key, message))
    return table.settings(**values)


def _device_table(c: Checker, table: str, doc: Any, settings: type) -> dict[str, Any] | None:
    """A GPIO device table (None when absent), its values checked by the driver's settings dataclass."""
    if doc is None:
        return None
    values = c.table(table, doc, SCHEMA[table])
    try:
        settings(**values)
    except DriverConfigError as exc:
        raise c.fail(table, None, str(exc)) from None
    return values


def _simulation_settings(c: Checker, base: Path, doc: Any) -> SimulationSettings:
    """[simulation], completed by its sensor (the simulated camera reads its camera file)."""
    values = c.table("simulation", doc, SCHEMA["simulation"])
    values["camera"] = _resolve(base, values["camera"])
    if values["sensor"] in sensor_registry.names():  # else SimulationSettings names the choices
        sensor_registry.sensor(values["sensor"]).simulation_values(
            values, functools.partial(c.fail, "simulation"))
    try:
        return SimulationSettings(**values)
    except InvalidInput as exc:
        raise ConfigError(f"{c.source}: [simulation]: {exc}") from None


def _hardware_settings(c: Checker, base: Path, doc: Any) -> HardwareSettings:
    """[hardware] and its device tables; the chosen sensor's table parsed by its sensor module."""
    schema = tables()
    hw = c.table("hardware", doc, schema["hardware"])
    sol = _device_table(c, "hardware.solenoid", hw["solenoid"], SolenoidSettings)
    assert sol is not None  # a required key of [hardware]
    btn = _device_table(c, "hardware.button", hw["button"], ButtonSettings)
    ind = _device_table(c, "hardware.indicator", hw["indicator"], IndicatorSettings)
    chosen = hw["sensor"]
    parsed: dict[str, Any] = {}
    for name, table in sensor_tables().items():
        where = f"hardware.{name}"
        if hw[name] is None:
            if name == chosen:
                raise c.fail("hardware", name, f"missing: sensor = \"{name}\" needs a [{where}] table ({table.needs})")
            continue
        keys = schema.get(where)
        values = dict(hw[name]) if keys is None else c.table(where, hw[name], keys)  # None: the driver's own keys
        if name != chosen:
            continue  # another sensor's table: its keys checked, not used
        for key, spec in (keys or {}).items():
            if spec.kind == "path":
                values[key] = _resolve(base, values[key])
        parsed[name] = table.read(values, functools.partial(c.fail, where))
    return HardwareSettings(gpio_backend=hw["gpio_backend"], sensor=chosen, solenoid=sol, button=btn,
                            indicator=ind, sensors=parsed)


def reference_markdown() -> str:
    """The configuration reference (the generated part of docs/service.md): every table and key."""
    L = ["| key | type | default | meaning |", "|---|---|---|---|"]
    out: list[str] = []
    for table, keys in tables().items():
        out.append(f"**[{table}]**")
        out.append("")
        out += L
        for k, spec in keys.items():
            if spec.default is REQUIRED:
                default = "**required**"
            elif spec.default is None:
                default = "–"
            elif isinstance(spec.default, bool):
                default = f"`{str(spec.default).lower()}`"
            elif isinstance(spec.default, dict):
                default = ", ".join(f"{e} {p}" for e, p in spec.default.items())
            else:
                default = f"`{spec.default!r}`".replace("'", '"') if isinstance(spec.default, str) else f"`{spec.default}`"
            kind = {"pinlike": "int or str", "videodevice": "str or int", "strlist": "list of str", "effects": "table",
                    "path": "path"}.get(spec.kind, spec.kind)
            doc = spec.doc + (f" ({', '.join(repr(c) for c in spec.choices)})" if spec.choices else "")
            out.append(f"| `{k}` | {kind} | {default} | {doc.replace('|', '/')} |")
        out.append("")
    return "\n".join(out)
