"""The appliance configuration: one TOML file, validated with one-line errors.

Every table and key is declared below (``SCHEMA``); an unknown key, a wrong
type, a value out of range or a missing hardware setting raises
``ConfigError`` naming the file, the table, the key and what was expected.
docs/service.md shows the whole file; examples/appliance.toml is a
commented example.

Without a ``[hardware]`` table (or with ``--sim``) the appliance runs on the
simulated rig described by ``[simulation]``.

The angle sensor is the Modbus encoder (``[hardware.encoder]``) or a camera
(``sensor = "camera"``, ``[hardware.camera]`` naming the V4L2 device and the
camera file of docs/vision.md). Camera files are read and checked here, so a
missing or malformed one is a configuration error naming both files.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from firmware_host import SequencerConfig
from measurement import Options, Rig
from measurement.effects import EFFECTS
from measurement.errors import InvalidInput

from .errors import ConfigError
from .files import read_rig, read_toml
from .modbus_server import ModbusSettings
from .mqtt import MqttSettings
from .registers import WORD_ORDERS

REQUIRED = object()

#: the angle sensors of ``[hardware] sensor``
SENSORS = ("encoder", "camera")

#: the rig simulated when ``[device] rig`` is not given (the demo rig of `moi demo`)
DEFAULT_SIM_RIG = Rig(kind="torsion", stiffness=0.3651, tare_inertia=4.5043e-3, declared=("viscous",))


# --- a small declarative schema ------------------------------------------------------------
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


def _seq_fields() -> dict[str, Key]:
    docs = {
        "pre_trigger": "capture before the release, s", "release_pulse": "solenoid pulse asked for, s",
        "capture_duration": "capture after the release (at most), s",
        "decay_threshold": "end the capture once the half peak-to-peak angle is below this, rad (0: off)",
        "decay_window": "window of the decay test, s", "min_capture": "no decay test before this, s",
        "sample_timeout": "no sample for this long → FAULT, s", "identify_timeout": "identification limit, s",
        "min_samples": "fewer samples → FAULT",
    }
    out: dict[str, Key] = {}
    for f in dataclasses.fields(SequencerConfig):
        if f.name == "identify_in_worker":
            continue  # the daemon always identifies in a worker (poll must stay responsive)
        kind = "int" if isinstance(f.default, int) and not isinstance(f.default, bool) else "float"
        out[f.name] = Key(kind, f.default, docs.get(f.name, ""), min=0)
    return out


SCHEMA: dict[str, dict[str, Key]] = {
    "device": {
        "id": Key("str", "moi", "device id: names the MQTT topics and Home Assistant entities"),
        "state_dir": Key("path", None, "result store directory (default $STATE_DIRECTORY, else ./moi-state)"),
        "rig": Key("path", None, "rig TOML file (required with [hardware]; relative paths are relative to this file)"),
        "log_level": Key("str", "info", "logging level", choices=("debug", "info", "warning", "error")),
        "store_trace": Key("bool", True, "keep the raw trace of every measurement in the store"),
    },
    "sequencer": _seq_fields(),
    "identification": {
        "discover": Key("bool", True, "run the discovery loop"),
        "candidates": Key("strlist", None, "effects the loop may add (default: all)"),
        "min_swings": Key("float", 3.0, "fewer full swings is an input error", min=0),
        "bic_margin": Key("float", 10.0, "an added effect must lower BIC by more than this", min=0),
    },
    "hardware": {
        "gpio_backend": Key("str", None, "gpiozero pin factory (lgpio on a Pi, mock for tests; default: gpiozero's)"),
        "sensor": Key("str", "encoder", "angle sensor: the Modbus encoder ([hardware.encoder]) or a camera "
                      "([hardware.camera])", choices=SENSORS),
        "solenoid": Key("table", REQUIRED, "[hardware.solenoid] pin, active_high, max_on_time"),
        "button": Key("table", None, "[hardware.button] pin, pull_up, bounce_time"),
        "indicator": Key("table", None, "[hardware.indicator] pin, kind, active_high"),
        "encoder": Key("table", None, "[hardware.encoder]: drivers.encoder.EncoderConfig (port, device_id, "
                       "baudrate, parity, register, registers, counts_per_turn, direction, zero, timeout, ...)"),
        "camera": Key("table", None, "[hardware.camera] device, file, max_lost_time "
                      "(required with sensor = \"camera\")"),
    },
    "hardware.solenoid": {
        "pin": Key("pinlike", REQUIRED, "BCM pin number or gpiozero pin name"),
        "active_high": Key("bool", True, "a high level energises the coil"),
        "max_on_time": Key("float", 0.5, "hard limit of one pulse, s", min=0, max=5.0, min_open=True),
    },
    "hardware.button": {
        "pin": Key("pinlike", REQUIRED, "BCM pin number or gpiozero pin name"),
        "pull_up": Key("bool", True, "pressed pulls the line low"),
        "bounce_time": Key("float", 0.05, "contact bounce suppression, s", min=0, max=1, min_open=True),
    },
    "hardware.indicator": {
        "pin": Key("pinlike", REQUIRED, "BCM pin number or gpiozero pin name"),
        "kind": Key("str", "led", "", choices=("led", "buzzer")),
        "active_high": Key("bool", True, ""),
    },
    "hardware.camera": {
        "device": Key("videodevice", REQUIRED, "V4L2 capture device: a path like \"/dev/video0\" (better: a stable "
                      "/dev/v4l/by-id/... link) or an index"),
        "file": Key("path", REQUIRED, "camera file: intrinsics, resolution and fps, marker radius and distance, "
                    "optional [pose] (docs/vision.md); relative to this file"),
        "max_lost_time": Key("float", 0.5, "no marker in the frames (lost or corrupt) for this long in a row → FAULT, "
                             "s (at least 5 frames)", min=0, min_open=True),
    },
    "simulation": {
        "inertia": Key("float", 0.0125, "true J of the simulated part, kg·m²", min=0, min_open=True),
        "effects": Key("effects", {"viscous": {"c": 1.5e-4}, "coulomb": {"Tc": 1.2e-4}},
                       "true damping: effect = { parameter = value }"),
        "theta0": Key("float", 0.25, "release angle, rad", min=0, max=3.0, min_open=True),
        "rate": Key("float", 200.0, "sample rate of the direct sensor, Hz", min=0, max=10000, min_open=True),
        "noise": Key("float", 1e-4, "angle noise σ, rad", min=0),
        "bits": Key("int", 17, "encoder resolution, bits per turn (0: none)", min=0, max=32),
        "time_scale": Key("float", 1.0, "simulated seconds per wall-clock second", min=0, max=1000, min_open=True),
        "seed": Key("int", None, "noise seed (default: random)"),
        "sensor": Key("str", "encoder", "\"encoder\": a simulated Modbus RTU encoder on a loopback socket read by the "
                      "real encoder client; \"direct\": an in-process sensor sampling at rate (faster); \"camera\": "
                      "a mock camera rendering the marker, read by the real camera sensor (keep time_scale = 1: "
                      "frames are rendered in real time)",
                      choices=("encoder", "direct", "camera")),
        "latency": Key("float", 0.0002, "simulated encoder reply latency, s of real time", min=0, max=1),
        "camera": Key("path", None, "camera file of the simulated camera (sensor = \"camera\"; default: the camera of "
                      "`moi measure --sensor camera`, 640×480 px at 100 frames/s, fx = 600 px, marker radius 0.10 m "
                      "at 0.25 m); relative to this file"),
        "camera_yaw_deg": Key("float", 0.0, "yaw of the simulated camera, degrees, within ±20 (estimated and "
                              "corrected by the sensor)", min=-20, max=20),
    },
    "mqtt": {
        "enabled": Key("bool", True, "publish over MQTT (the table's presence enables it)"),
        "host": Key("str", "localhost", "broker host"),
        "port": Key("int", 1883, "broker port", min=1, max=65535),
        "prefix": Key("str", "moi", "topic prefix: topics are <prefix>/<device id>/..."),
        "client_id": Key("str", None, "MQTT client id (default moi-<device id>)"),
        "username": Key("str", None, ""),
        "password": Key("str", None, "prefer password_file"),
        "password_file": Key("path", None, "file holding the password (e.g. a systemd credential)"),
        "keepalive": Key("int", 30, "s", min=5, max=3600),
        "tls": Key("bool", False, "connect with TLS"),
        "ca_file": Key("path", None, "CA certificate(s) for the broker (default: the system's)"),
        "cert_file": Key("path", None, "client certificate (mutual TLS)"),
        "key_file": Key("path", None, "client key (mutual TLS)"),
        "tls_insecure": Key("bool", False, "skip the broker host name check (testing only)"),
        "reconnect_min": Key("float", 0.5, "first reconnect delay, s", min=0, min_open=True),
        "reconnect_max": Key("float", 30.0, "longest reconnect delay, s", min=0, min_open=True),
        "resend_after": Key("float", 30.0, "re-send a result not acknowledged after this, s", min=0, min_open=True),
        "home_assistant": Key("bool", False, "publish Home Assistant discovery messages"),
        "discovery_prefix": Key("str", "homeassistant", "Home Assistant discovery prefix"),
    },
    "recipes": {
        "directory": Key("path", None, "directory of the recipe files, one TOML file per part type (docs/service.md, "
                         "Recipes); relative to this file"),
        "active": Key("str", None, "recipe active at start (name or number); the PLC (register recipe_select) or "
                      "MQTT (cmd/recipe) may change it"),
    },
    "modbus": {
        "enabled": Key("bool", True, "serve the registers"),
        "mode": Key("str", "tcp", "Modbus TCP server or Modbus RTU slave on a serial line", choices=("tcp", "rtu")),
        "host": Key("str", "0.0.0.0", "TCP listen address"),
        "port": Key("int", 5020, "TCP port (502 needs CAP_NET_BIND_SERVICE; 0: any free port)", min=0, max=65535),
        "unit_id": Key("int", 1, "Modbus unit (device) id answered", min=1, max=247),
        "word_order": Key("str", "big", "order of the two registers of a float32/uint32", choices=WORD_ORDERS),
        "serial_port": Key("str", None, "RTU: serial device, e.g. /dev/ttyAMA0"),
        "baudrate": Key("int", 19200, "RTU baud rate", min=300, max=4_000_000),
        "parity": Key("str", "E", "RTU parity", choices=("N", "E", "O")),
        "stopbits": Key("int", 1, "RTU stop bits", choices=(1, 2)),
        "bytesize": Key("int", 8, "RTU data bits", choices=(7, 8)),
    },
}

#: tables that are plain key/value tables of SCHEMA (the others are sub-tables)
TOP_TABLES = ("device", "sequencer", "identification", "hardware", "simulation", "mqtt", "modbus", "recipes")


# --- the validated configuration ----------------------------------------------------------------
@dataclass(frozen=True)
class SimulationSettings:
    inertia: float = 0.0125
    effects: Mapping[str, Mapping[str, float]] = field(default_factory=lambda: {"viscous": {"c": 1.5e-4}})
    theta0: float = 0.25
    rate: float = 200.0
    noise: float = 1e-4
    bits: int = 17
    time_scale: float = 1.0
    seed: int | None = None
    sensor: str = "encoder"
    latency: float = 0.0002
    camera: str | None = None        # camera file (resolved), None: the demo camera
    camera_yaw_deg: float = 0.0
    camera_config: Any = None        # the parsed camera file (CameraConfig) with sensor = "camera"


@dataclass(frozen=True)
class CameraSettings:
    """``[hardware.camera]``: the V4L2 device, the camera file (path and parsed content), the lost-marker limit."""

    device: str | int
    file: str
    max_lost_time: float
    config: Any  # measurement.vision.CameraConfig (imported lazily: it loads OpenCV)


@dataclass(frozen=True)
class HardwareSettings:
    gpio_backend: str | None
    sensor: str
    solenoid: Mapping[str, Any]
    button: Mapping[str, Any] | None
    indicator: Mapping[str, Any] | None
    encoder: Mapping[str, Any] | None
    camera: CameraSettings | None = None


@dataclass(frozen=True)
class Config:
    """The whole validated configuration (SI units)."""

    source: str                      # the file it came from ("<defaults>" when none)
    device_id: str
    state_dir: Path
    log_level: str
    store_trace: bool
    rig: Rig
    rig_path: str | None
    simulated: bool
    simulation: SimulationSettings
    hardware: HardwareSettings | None
    sequencer: SequencerConfig
    identification: Options
    mqtt: MqttSettings | None        # None: MQTT off
    modbus: ModbusSettings | None    # None: Modbus off
    document: Mapping[str, Any]      # the parsed TOML, stored with every measurement
    recipes: Any = None              # service.recipes.RecipeBook (every recipe of [recipes] directory, checked)
    active_recipe: str | None = None  # [recipes] active

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary of what the daemon runs with (passwords left out)."""
        def clean(obj: Any) -> Any:
            if obj is None:
                return None
            d = dataclasses.asdict(obj)
            for secret in ("password",):
                if d.get(secret):
                    d[secret] = "***"
            return d
        return {
            "source": self.source, "device_id": self.device_id, "state_dir": str(self.state_dir),
            "rig_path": self.rig_path, "rig": self.rig.to_dict(), "simulated": self.simulated,
            "simulation": clean(self.simulation) if self.simulated else None,
            "hardware": clean(self.hardware), "sequencer": clean(self.sequencer),
            "identification": clean(self.identification), "mqtt": clean(self.mqtt), "modbus": clean(self.modbus),
            "recipes": None if self.recipes is None else {
                "directory": self.recipes.directory, "active": self.active_recipe,
                "recipes": [{"name": r.name, "number": r.number, "version": r.version, "path": r.path}
                            for r in self.recipes.recipes]},
        }


# --- validation ------------------------------------------------------------------------------------
class _Checker:
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
        k = spec.kind
        if k in ("str", "path"):
            if not isinstance(v, str) or (k == "path" and not v):
                raise bad
        elif k == "pinlike":
            if isinstance(v, bool) or not isinstance(v, (int, str)) or (isinstance(v, int) and v < 0) or v == "":
                raise self.fail(table, key, f"expected a BCM pin number >= 0 or a name like 'GPIO17', got {v!r}")
        elif k == "videodevice":
            if isinstance(v, bool) or not isinstance(v, (int, str)) or (isinstance(v, int) and v < 0) or v == "":
                raise bad
            if isinstance(v, str) and v.isdigit():
                v = int(v)  # "0": the index, not a file named 0
        elif k == "bool":
            if not isinstance(v, bool):
                raise bad
        elif k == "int":
            if isinstance(v, bool) or not isinstance(v, int):
                raise bad
        elif k == "float":
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise bad
            v = float(v)
        elif k == "strlist":
            if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
                raise bad
            v = tuple(v)
        elif k == "table":
            if not isinstance(v, Mapping):
                raise bad
            v = dict(v)
        elif k == "effects":
            v = self.effects(table, key, v)
        if spec.choices is not None and v not in spec.choices:
            raise bad
        if k in ("int", "float"):
            if spec.min is not None and (v < spec.min or (spec.min_open and v == spec.min)):
                raise bad
            if spec.max is not None and v > spec.max:
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


def parse_config(doc: Mapping[str, Any], *, source: str = "<config>", base: Path | None = None, sim: bool = False,
                 state_dir: str | None = None, environ: Mapping[str, str] | None = None) -> Config:
    c = _Checker(source)
    base = base or Path.cwd()
    unknown = [t for t in doc if t not in TOP_TABLES]
    if unknown:
        t = unknown[0]
        close = difflib.get_close_matches(t, TOP_TABLES, n=1)
        hint = f" (did you mean [{close[0]}]?)" if close else f"; expected tables: {', '.join(f'[{x}]' for x in TOP_TABLES)}"
        kind = "table" if isinstance(doc[t], Mapping) else "top-level key"
        raise ConfigError(f"{source}: unknown {kind} {t!r}{hint}")

    dev = c.table("device", doc.get("device", {}), SCHEMA["device"])
    if not dev["id"] or any(ch in dev["id"] for ch in "/#+ ") or len(dev["id"]) > 64:
        raise c.fail("device", "id", f"expected 1–64 characters without '/', '#', '+' or spaces (it is an MQTT topic level), got {dev['id']!r}")
    seq_doc = c.table("sequencer", doc.get("sequencer", {}), SCHEMA["sequencer"])
    try:
        seq_cfg = SequencerConfig(**seq_doc, identify_in_worker=True)
    except InvalidInput as exc:
        raise ConfigError(f"{source}: [sequencer]: {exc}") from None
    ident = c.table("identification", doc.get("identification", {}), SCHEMA["identification"])
    if ident["candidates"] is not None:
        for name in ident["candidates"]:
            if name not in EFFECTS:
                raise c.fail("identification", "candidates", f"unknown effect {name!r}; expected names from {', '.join(EFFECTS)}")
    options = Options(discover=ident["discover"], candidates=ident["candidates"], min_swings=ident["min_swings"],
                      bic_margin=ident["bic_margin"])

    hardware = None
    if "hardware" in doc:
        hw = c.table("hardware", doc["hardware"], SCHEMA["hardware"])
        sol = c.table("hardware.solenoid", hw["solenoid"], SCHEMA["hardware.solenoid"])
        btn = c.table("hardware.button", hw["button"], SCHEMA["hardware.button"]) if hw["button"] is not None else None
        ind = c.table("hardware.indicator", hw["indicator"], SCHEMA["hardware.indicator"]) if hw["indicator"] is not None else None
        enc = hw["encoder"]
        if hw["sensor"] == "encoder":
            if enc is None:
                raise c.fail("hardware", "encoder", "missing: sensor = \"encoder\" needs a [hardware.encoder] table "
                              "(port, device id, register, counts per turn)")
            _check_encoder_keys(c, enc)
        camera = None
        if hw["camera"] is not None:
            cam = c.table("hardware.camera", hw["camera"], SCHEMA["hardware.camera"])
            if hw["sensor"] == "camera":
                file = _resolve(base, cam["file"])
                camera = CameraSettings(device=cam["device"], file=file, max_lost_time=cam["max_lost_time"],
                                        config=_read_camera(c, "hardware.camera", "file", file))
        elif hw["sensor"] == "camera":
            raise c.fail("hardware", "camera", "missing: sensor = \"camera\" needs a [hardware.camera] table "
                          "(device = \"/dev/video0\", file = the camera file)")
        hardware = HardwareSettings(hw["gpio_backend"], hw["sensor"], sol, btn, ind, enc, camera)

    sim_doc = c.table("simulation", doc.get("simulation", {}), SCHEMA["simulation"])
    sim_doc["camera"] = _resolve(base, sim_doc["camera"])
    if sim_doc["sensor"] == "camera":
        sim_doc["camera_config"] = _read_camera(c, "simulation", "camera", sim_doc["camera"])
    simulation = SimulationSettings(**sim_doc)
    simulated = sim or hardware is None

    rig_path = _resolve(base, dev["rig"])
    if rig_path is not None:
        try:
            rig = read_rig(rig_path)
        except InvalidInput as exc:
            raise ConfigError(f"{source}: [device] rig: {exc}") from None
    elif not simulated:
        raise c.fail("device", "rig", "missing: a rig file (kind, stiffness or mass/com_distance, declared effects) "
                      "is required with [hardware]")
    else:
        rig = DEFAULT_SIM_RIG
    if simulated:
        try:
            from measurement import Pendulum
            # resolves the effects on this rig and checks their parameter names
            Pendulum(rig, simulation.inertia, simulation.effects).parameter_vector(simulation.theta0)
        except InvalidInput as exc:
            raise ConfigError(f"{source}: [simulation]: {exc}") from None

    mqtt = None
    if "mqtt" in doc:
        m = c.table("mqtt", doc["mqtt"], SCHEMA["mqtt"])
        if m.pop("enabled"):
            for k in ("password_file", "ca_file", "cert_file", "key_file"):
                m[k] = _resolve(base, m[k])
            if m["password"] is not None and m["password_file"] is not None:
                raise c.fail("mqtt", "password", "give password or password_file, not both")
            if (m["password"] is not None or m["password_file"] is not None) and m["username"] is None:
                raise c.fail("mqtt", "username", "missing: a password needs a username")
            if (m["cert_file"] is None) != (m["key_file"] is None):
                raise c.fail("mqtt", "cert_file", "give both cert_file and key_file for mutual TLS, or neither")
            if not m["tls"] and any(m[k] for k in ("ca_file", "cert_file", "key_file")):
                raise c.fail("mqtt", "tls", "ca_file/cert_file/key_file are set but tls = false")
            if m["reconnect_max"] < m["reconnect_min"]:
                raise c.fail("mqtt", "reconnect_max", "must be >= reconnect_min")
            if not m["prefix"].strip("/") or any(ch in m["prefix"] for ch in "#+"):
                raise c.fail("mqtt", "prefix", f"expected topic levels without '#' or '+', got {m['prefix']!r}")
            mqtt = MqttSettings(**m)

    modbus = None
    mb = c.table("modbus", doc.get("modbus", {}), SCHEMA["modbus"])
    if mb.pop("enabled"):
        if mb["mode"] == "rtu" and not mb["serial_port"]:
            raise c.fail("modbus", "serial_port", "missing: mode = \"rtu\" needs the serial device, e.g. /dev/ttyAMA0")
        modbus = ModbusSettings(**mb)

    from .recipes import RecipeBook
    rc = c.table("recipes", doc.get("recipes", {}), SCHEMA["recipes"])
    book = RecipeBook.load(_resolve(base, rc["directory"]))  # RecipeError: one line naming the recipe file
    if rc["active"] is not None:
        try:
            book.find(rc["active"])
        except ConfigError as exc:
            raise c.fail("recipes", "active", str(exc)) from None

    sd = state_dir or _resolve(base, dev["state_dir"])
    return Config(
        source=source, device_id=dev["id"],
        state_dir=Path(sd) if sd else default_state_dir(environ),
        log_level=dev["log_level"], store_trace=dev["store_trace"],
        rig=rig, rig_path=rig_path, simulated=simulated, simulation=simulation, hardware=hardware,
        sequencer=seq_cfg, identification=options, mqtt=mqtt, modbus=modbus, document=dict(doc),
        recipes=book, active_recipe=rc["active"],
    )


def _check_encoder_keys(c: _Checker, enc: Mapping[str, Any]) -> None:
    """[hardware.encoder] is the encoder driver's own settings table: let the driver check it."""
    from drivers.encoder import EncoderConfig
    from drivers.errors import DriverConfigError

    try:
        EncoderConfig.from_dict(dict(enc))
    except DriverConfigError as exc:
        raise c.fail("hardware.encoder", None, str(exc)) from None


def _read_camera(c: _Checker, table: str, key: str, path: str | None) -> Any:
    """The camera file at ``path`` (None: the demo camera of `moi measure`) as a ``CameraConfig``;
    a missing or malformed file is a one-line error naming the config file, the key and the camera file."""
    from measurement.vision.config import CameraConfig

    from .camera_config import read_camera
    if path is None:
        from .commands.measure import DEFAULT_CAMERA
        return CameraConfig.from_dict(DEFAULT_CAMERA)
    try:
        return read_camera(path)
    except InvalidInput as exc:  # InputFileError (not found, not TOML) or VisionError (naming the file)
        raise c.fail(table, key, str(exc)) from None


def reference_markdown() -> str:
    """The configuration reference (the generated part of docs/service.md): every table and key."""
    L = ["| key | type | default | meaning |", "|---|---|---|---|"]
    out: list[str] = []
    for table, keys in SCHEMA.items():
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
