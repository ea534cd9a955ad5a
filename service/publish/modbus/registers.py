"""The Modbus register map: one table that the server serves and `docs/modbus.md` is generated from.

Everything the PLC reads is encoded here from the published result payload
(``service.publish.payload.result_payload``, itself built from
``IdentificationResult.to_dict()``), so the registers and the MQTT JSON
cannot disagree. The server (``service.publish.modbus.server``) only copies the
register image produced here; ``decode_image`` is the inverse a client uses
(tests, bench, ``moi modbus-map --read``).

Addresses are 0-based protocol addresses (the "PDU address"); PLC tools
that count from 1 (4x0001 / 3x0001 style) add 1.
"""

from __future__ import annotations

import math
import struct
import uuid as uuidlib
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping, Sequence

from drivers.modbus_words import WORD_ORDERS, check_word_order, from_registers, to_registers  # noqa: F401
from service.parts.recipes import PART_ID_LENGTH
from service.publish.replies import REASONS
from service.states import STATES
from measurement import flags as F
from measurement.tensor import COMPONENTS

#: bumped whenever an address or an encoding in this file changes; what each version changed is in CHANGELOG.md
MAP_VERSION = 12


# --- enumerations ------------------------------------------------------------

#: sequencer/daemon state → code in register `state`
STATE_CODES: dict[str, int] = {name: s.code for name, s in STATES.items()}
STATE_OTHER = 255

#: quality flag (``measurement.flags.FLAGS``, which says what each means) → bit in register `flags`.
#: A flag not in this table sets FLAG_OTHER_BIT, so a new flag is never silently lost.
FLAG_BITS: dict[str, int] = {
    F.UNMODELED_RESIDUAL: 0,
    F.OUTLIERS_REMOVED: 1,
    F.PARAMETER_AT_BOUND: 2,
    F.FIT_NOT_CONVERGED: 3,
    F.CORRELATED_RESIDUAL: 4,
    F.ENCODER_ERRORS: 5,
    F.CAMERA_POSE: 6,
    F.MARKER_LOST: 7,
    F.DROPPED_FRAMES: 8,
    F.CORRUPT_FRAME: 9,   # map version 2; in version 1 it set bit 15 (other)
    F.OUTLIERS_DOWNWEIGHTED: 10,  # map version 3
    F.WINDOW_CUT_AT_GAP: 11,
    F.ANGLE_UNWRAPPED: 12,
    F.CALIBRATION_DUE: 13,  # map version 4: the rig's calibration is past its validity period
    F.NEGATIVE_INERTIA: 14,  # map version 4
    F.SENSOR_SCALE_FITTED: 16,  # map version 5: register flags_high, bit 0
    F.CAMERA_PERSPECTIVE: 17,  # map version 6: register flags_high, bit 1
    F.TENSOR_INCONSISTENT: 18,  # map version 7: a tensor set's flags (register flags_high / tensor_flags)
    F.TENSOR_UNPHYSICAL: 19,
    F.ORIENTATION_EXCLUDED: 20,
    F.HALVES_DISAGREE: 21,  # map version 8: the model's form (register flags_high, bits 5-7)
    F.MODEL_AMBIGUOUS: 22,
    F.RELEASES_DISAGREE: 23,
    F.CAPTURE_SLOWED: 24,  # map version 12: register flags_high, bit 8
}
FLAG_OTHER_BIT = 15

#: effect of the final model → bit in register `effects`
EFFECT_BITS: dict[str, int] = {
    "viscous": 0,
    "coulomb": 1,
    "quadratic": 2,
    "cubic_stiffness": 3,
    "drift": 4,
    "gain": 5,  # map version 3
    "dahl": 6,  # map version 5
    "view": 7,  # map version 5
}
EFFECT_OTHER_BIT = 15

#: bits of register `status` (also served as discrete inputs at the same bit numbers)
STATUS_BITS: dict[str, int] = {
    "busy": 0,            # a measurement is running (ARMED … PUBLISHING)
    "result_valid": 1,    # the snapshot holds a result the PLC has not acknowledged (plc_status bit 2 too)
    "fault": 2,           # the sequencer is in FAULT
    "mqtt_connected": 3,  # the MQTT client is connected to its broker
    "simulated": 4,       # the appliance runs on the simulated rig
    "outbox_pending": 5,  # results wait in the outbox for the broker
    "part_ok": 6,         # the snapshot's part verdict is OK (a PLC latches on it)
    "part_nok": 7,        # ... NOK
    "part_invalid": 8,    # ... INVALID (not trustworthy: measure again)
}

#: bits of register `plc_status`, the handshake's status word (the bits integrators know from vision sensors)
PLC_STATUS_BITS: dict[str, int] = {
    "ready": 0,                  # IDLE: a trigger is accepted now
    "busy": 1,                   # a measurement runs (ARMED … PUBLISHING)
    "result_valid": 2,           # the snapshot block shows a result not yet acknowledged (latest mode: a result)
    "result_buffer_overrun": 3,  # a result found the queue full (see overrun_count); cleared by acknowledge_fault
    "error": 4,                  # error_code is not 0
    "calibration_due": 5,        # the rig's calibration is past its validity period
    "not_decidable": 6,          # the shown result's verdict is INVALID or lies in the guard band's uncertainty range
    "trigger_ack": 7,            # the trigger in `command` was accepted; cleared when the PLC writes `command` again
    "plc_heartbeat_lost": 8,     # the PLC's heartbeat (register 114) did not change for [modbus] plc_heartbeat_timeout
}

#: register `error_code`: code → (name, meaning); the highest-priority cause present is shown
ERROR_CODES: dict[int, tuple[str, str]] = {
    0: ("none", "no error"),
    1: ("fault", "the sequencer is in FAULT (a sensor, the solenoid or the identification failed; the reason is "
                 "on the web page and in the MQTT state): acknowledge it with command 3 or coil 1"),
    2: ("store_unwritable", "the result store cannot be written (disk full?): measurements are refused"),
    3: ("plc_heartbeat_lost", "the PLC's heartbeat register did not change for plc_heartbeat_timeout"),
    4: ("result_buffer_overrun", "a result found the queue full and is not shown (still stored and sent over "
                                 "MQTT); acknowledge with command 3"),
}
ERROR_CODE_BY_NAME: dict[str, int] = {name: code for code, (name, _) in ERROR_CODES.items()}

#: register `command`: code → name (the daemon's command it queues)
COMMANDS: dict[int, str] = {1: "trigger", 2: "abort", 3: "acknowledge_fault", 4: "select_recipe"}
COMMAND_CODES: dict[str, int] = {name: code for code, name in COMMANDS.items()}

#: register `command_status`
COMMAND_STATUS: dict[str, int] = {"none": 0, "accepted": 1, "refused": 2, "done": 3, "failed": 4}

#: the appliance increments `heartbeat` this often while its main loop runs, s
HEARTBEAT_PERIOD = 0.5

#: verdict → code in registers `verdict` and `release_verdict` (0: none yet / part not complete / no recipe)
VERDICT_CODES: dict[str, int] = {"OK": 1, "NOK": 2, "INVALID": 3}

#: characters of the part ID block (2 ASCII characters per register, first character in the high byte)
PART_ID_CHARS = PART_ID_LENGTH  # the recipes' rule; two characters per register

#: the only writable holding registers (FC 6 / FC 16): name → (address, count). Read back with FC 3.
WRITABLE: dict[str, tuple[int, int]] = {
    "part_id": (100, PART_ID_CHARS // 2),  # the next part's serial number, ASCII, NUL-padded
    "recipe_select": (110, 1),             # the recipe number to make active (0: none)
    "command": (111, 1),                   # a command code (COMMANDS), 0: none
    "command_parameter": (112, 1),         # the command's parameter (select_recipe: the recipe number)
    "result_ack": (113, 1),                # acknowledge the shown result: write its `seq`
    "plc_heartbeat": (114, 1),             # a counter the PLC changes; its silence raises plc_heartbeat_lost
}
#: the writable registers that say which part is measured: refused while a measurement runs
PART_INPUTS = ("part_id", "recipe_select")
WRITABLE_START = min(a for a, _ in WRITABLE.values())
WRITABLE_END = max(a + n for a, n in WRITABLE.values())  # exclusive

#: coils (FC1 read, FC5/FC15 write). Only these are writable on the whole device.
COILS: dict[str, int] = {
    "trigger": 0,  # write 1: start one measurement (reads back 0)
    "abort": 1,    # write 1: abort the running measurement (reads back 0)
    "set_redo": 2,   # write 1: tensor set, measure the current orientation again (or the previous one)
    "set_skip": 3,   # write 1: tensor set, skip the current orientation
    "set_abort": 4,  # write 1: tensor set, abort the set (its releases stay stored)
}


def flag_bits(flags: Iterable[str]) -> int:
    """Bit field of quality flags; unknown flags set bit FLAG_OTHER_BIT."""
    bits = 0
    for f in flags:
        bits |= 1 << FLAG_BITS.get(f, FLAG_OTHER_BIT)
    return bits


def flags_from_bits(bits: int) -> list[str]:
    """Flag names of a bit field (``flags`` | ``flags_high`` << 16); "other" for bit FLAG_OTHER_BIT."""
    names = [name for name, b in FLAG_BITS.items() if bits & (1 << b)]
    if bits & (1 << FLAG_OTHER_BIT):
        names.append("other")
    return names


def effect_bits(effects: Iterable[str]) -> int:
    bits = 0
    for e in effects:
        bits |= 1 << EFFECT_BITS.get(e, EFFECT_OTHER_BIT)
    return bits


def state_code(name: str | None) -> int:
    return STATE_CODES.get(str(name).upper(), STATE_OTHER) if name is not None else STATE_CODES["STARTING"]


def modbus_seq(seq: int) -> int:
    """The measurement sequence counter as served: 1…65535, wrapping past 0 (0 = no result yet)."""
    if seq <= 0:
        return 0
    return (seq - 1) % 0xFFFF + 1


# --- register table ----------------------------------------------------------

_KIND_COUNT = {"uint16": 1, "bits16": 1, "uint32": 2, "float32": 2, "uuid": 8, "ascii20": PART_ID_CHARS // 2}


@dataclass(frozen=True)
class Register:
    """One value in the input-register image.

    kind: uint16 | bits16 | uint32 | float32 | uuid (16 bytes, 8 registers, RFC 4122 byte order) |
    ascii20 (20 ASCII characters, 2 per register, first in the high byte, NUL-padded).
    source: the payload/live key the value comes from (documentation and encoder).
    """

    name: str
    address: int
    kind: str
    unit: str
    description: str
    source: str
    area: str  # "live" | "snapshot"

    @property
    def count(self) -> int:
        return _KIND_COUNT[self.kind]


def _table() -> tuple[Register, ...]:
    rows: list[Register] = []

    def add(area: str, address: int, name: str, kind: str, unit: str, source: str, description: str) -> None:
        rows.append(Register(name, address, kind, unit, description, source, area))

    # Live status: changes at any time, not part of the result snapshot.
    add("live", 0, "map_version", "uint16", "", "constant", f"version of this register map ({MAP_VERSION})")
    add("live", 1, "state", "uint16", "enum", "state",
        "sequencer state: " + ", ".join(f"{v} {k}" for k, v in STATE_CODES.items()) + f", {STATE_OTHER} other")
    add("live", 2, "status", "bits16", "bits",
        "status", "status bits: " + ", ".join(f"bit {b} {n}" for n, b in STATUS_BITS.items()))
    add("live", 3, "measurements_started", "uint16", "count", "started",
        "measurements started since the daemon started (wraps at 65536); increments when a trigger is accepted")
    add("live", 4, "outbox_pending", "uint16", "count", "outbox_pending",
        "results not yet acknowledged by the MQTT broker (saturates at 65535)")
    add("live", 5, "recipe", "uint16", "", "recipe", "number of the active recipe (0: none)")
    add("live", 6, "part_releases_done", "uint16", "count", "releases_done",
        "releases of the part in progress so far (0 when no part is open)")
    add("live", 7, "set_step", "uint16", "count", "set_step",
        "tensor set: the step now to measure, 1…set_steps (0: no set running)")
    add("live", 8, "set_steps", "uint16", "count", "set_steps", "tensor set: its number of orientations (0: no set)")
    add("live", 9, "set_orientation", "uint16", "", "set_orientation",
        "tensor set: the orientation to mount now, its number in the recipe's plan (1-based; 0: none). The "
        "recipe's [[tensor.orientation]] tables, in order, say which axis each number is")

    # Result snapshot: written as one unit (see the snapshot protocol).
    add("snapshot", 10, "seq", "uint16", "count", "seq",
        "measurement sequence counter of the result below (the MQTT `seq` modulo 65535: 1…65535 then 1 again); "
        "0 = no result yet")
    add("snapshot", 11, "timestamp", "uint32", "s", "finished_at",
        "end of the measurement, Unix time (UTC seconds)")
    add("snapshot", 13, "J", "float32", "kg·m²", "J", "moment of inertia about the pivot (NaN when the rig lacks k or m·S)")
    add("snapshot", 15, "J_std", "float32", "kg·m²", "J_std", "1σ standard uncertainty of J")
    add("snapshot", 17, "omega_n", "float32", "rad/s", "omega_n", "small-amplitude natural angular frequency ω_n")
    add("snapshot", 19, "omega_n_std", "float32", "rad/s", "omega_n_std", "1σ of ω_n")
    add("snapshot", 21, "damping_ratio", "float32", "1", "damping_ratio",
        "equivalent viscous damping ratio ζ at the reference amplitude")
    add("snapshot", 23, "damping_ratio_std", "float32", "1", "damping_ratio_std", "1σ of ζ")
    add("snapshot", 25, "residual_rms", "float32", "rad", "residual_rms_after", "residual RMS of the final model (after discovery)")
    add("snapshot", 27, "residual_rms_before", "float32", "rad", "residual_rms_before",
        "residual RMS of the declared model (before discovery)")
    add("snapshot", 29, "noise_floor", "float32", "rad", "noise_floor", "angle noise floor estimated from the data")
    add("snapshot", 31, "J_object", "float32", "kg·m²", "J_object", "J − tare inertia (NaN without a tare)")
    add("snapshot", 33, "flags", "bits16", "bits", "flags",
        "quality flags: " + ", ".join(f"bit {b} {n}" for n, b in FLAG_BITS.items() if b < 16)
        + f", bit {FLAG_OTHER_BIT} other")
    add("snapshot", 34, "effects", "bits16", "bits", "effects",
        "effects of the final model: " + ", ".join(f"bit {b} {n}" for n, b in EFFECT_BITS.items()) + f", bit {EFFECT_OTHER_BIT} other")
    add("snapshot", 35, "uuid", "uuid", "", "uuid", "result UUID (the MQTT `uuid`), 16 bytes big-endian, 2 bytes per register")
    codes = ", ".join(f"{v} {k}" for k, v in VERDICT_CODES.items())
    add("snapshot", 43, "verdict", "uint16", "enum", "verdict",
        f"the part's verdict once this release completed it: {codes}; 0 while the part is incomplete or without a recipe")
    add("snapshot", 44, "release_verdict", "uint16", "enum", "release_verdict", f"this release's own verdict: {codes}; 0 without a recipe")
    add("snapshot", 45, "release_index", "uint16", "count", "release_index", "this release is number … of the part (1-based; 0 without a recipe)")
    add("snapshot", 46, "releases", "uint16", "count", "releases", "releases per part of the recipe")
    add("snapshot", 47, "recipe_number", "uint16", "", "recipe_number", "number of the recipe the release was judged with (0: none)")
    add("snapshot", 48, "part_value", "float32", "kg·m²", "part_value",
        "the part's value of the recipe quantity (its usable releases identified jointly; NaN until complete)")
    add("snapshot", 50, "part_U", "float32", "kg·m²", "part_U", "expanded uncertainty U of part_value (NaN until complete)")
    add("snapshot", 52, "part_id", "ascii20", "", "part_id", "the part ID the release was measured for (echo of registers 100–109)")
    add("snapshot", 62, "flags_high", "bits16", "bits", "flags_high",
        "more quality flags: " + ", ".join(f"bit {b - 16} {n}" for n, b in FLAG_BITS.items() if b >= 16))
    add("snapshot", 63, "J_U", "float32", "kg·m²", "J_U",
        "expanded uncertainty U of J from its uncertainty budget (coverage factor in the result, k = 2 unless "
        "few degrees of freedom call for more; NaN when J is unknown)")
    add("snapshot", 65, "J_object_U", "float32", "kg·m²", "J_object_U",
        "expanded uncertainty U of J_object, the k–I0 correlation of the calibration kept (NaN without a tare)")
    add("snapshot", 67, "seq_end", "uint16", "count", "seq", "copy of `seq`, the last register of the snapshot")

    # The PLC handshake: live, at a fixed address past the snapshot (which may grow up to it), so that
    # registers 0…88 are one request.
    add("handshake", HANDSHAKE_START + 0, "plc_status", "bits16", "bits", "plc_status",
        "handshake status word: " + ", ".join(f"bit {b} {n}" for n, b in PLC_STATUS_BITS.items()))
    add("handshake", HANDSHAKE_START + 1, "error_code", "uint16", "enum", "error_code", "error code, see the table below (0: none)")
    add("handshake", HANDSHAKE_START + 2, "heartbeat", "uint16", "count", "heartbeat",
        f"incremented every {HEARTBEAT_PERIOD:g} s while the appliance's main loop runs (wraps at 65536); a value "
        "that stops changing means the appliance hangs")
    add("handshake", HANDSHAKE_START + 3, "results_queued", "uint16", "count", "results_queued",
        "results waiting for the PLC's acknowledgement, the one shown included (mode ack; latest: 0 or 1)")
    add("handshake", HANDSHAKE_START + 4, "overrun_count", "uint16", "count", "overrun_count",
        "results that found the queue full since the daemon started (saturates at 65535)")
    add("handshake", HANDSHAKE_START + 5, "command_echo", "uint16", "enum", "command_echo",
        "the command code the status below belongs to (" + ", ".join(f"{c} {n}" for c, n in COMMANDS.items()) + ")")
    add("handshake", HANDSHAKE_START + 6, "command_status", "uint16", "enum", "command_status",
        "its status: " + ", ".join(f"{c} {n}" for n, c in COMMAND_STATUS.items()))
    add("handshake", HANDSHAKE_START + 7, "command_reason", "uint16", "enum", "command_reason",
        "why it was refused or failed (0: it was not): " + ", ".join(f"{r.code} {n}" for n, r in REASONS.items()))
    add("handshake", HANDSHAKE_START + 8, "command_count", "uint16", "count", "command_count",
        "incremented with every change of the command status (wraps at 65536): the PLC waits for it to change")

    # The tensor of the latest tensor set: a block of its own, with its own snapshot protocol.
    a = TENSOR_START
    add("tensor", a, "tensor_seq", "uint16", "count", "tensor_seq",
        "tensor sets completed since the daemon started (1…65535, wrapping past 0); 0 = no tensor yet")
    for i, c in enumerate(TENSOR_COMPONENTS):
        add("tensor", a + 1 + 2 * i, c, "float32", "kg·m²", c,
            f"inertia tensor component {c} about the centre of mass, part frame (products in the recipe's "
            "poi_convention, see docs/tensor.md)")
    for i, c in enumerate(TENSOR_COMPONENTS):
        add("tensor", a + 13 + 2 * i, f"{c}_U", "float32", "kg·m²", f"{c}_U", f"expanded uncertainty U of {c} (k = 2)")
    for i in range(3):
        add("tensor", a + 25 + 2 * i, f"I{i + 1}", "float32", "kg·m²", f"I{i + 1}",
            f"principal moment {i + 1} (ascending)")
    for i in range(3):
        add("tensor", a + 31 + 2 * i, f"I{i + 1}_U", "float32", "kg·m²", f"I{i + 1}_U",
            f"expanded uncertainty U of principal moment {i + 1} (k = 2)")
    add("tensor", a + 37, "tensor_flags", "bits16", "bits", "tensor_flags",
        "the tensor's flags, the bits of `flags_high`: " + ", ".join(
            f"bit {b - 16} {n}" for n, b in FLAG_BITS.items() if n in TENSOR_FLAGS))
    add("tensor", a + 38, "tensor_seq_end", "uint16", "count", "tensor_seq", "copy of `tensor_seq`, the block's last register")
    return tuple(rows)


#: the handshake block's first address (the snapshot ends before it)
HANDSHAKE_START = 80

#: the tensor block: the first address, the components in their order (``measurement.tensor.COMPONENTS``)
TENSOR_START = 200
TENSOR_COMPONENTS = COMPONENTS
TENSOR_FLAGS = (F.TENSOR_INCONSISTENT, F.TENSOR_UNPHYSICAL, F.ORIENTATION_EXCLUDED)

REGISTERS: tuple[Register, ...] = _table()
BY_NAME: dict[str, Register] = {r.name: r for r in REGISTERS}
LIVE_START = 0
SNAPSHOT_START = BY_NAME["seq"].address
SNAPSHOT_END = BY_NAME["seq_end"].address + 1  # exclusive
HANDSHAKE_END = BY_NAME["command_count"].address + 1  # exclusive
IMAGE_SIZE = HANDSHAKE_END  # registers 0 … IMAGE_SIZE-1
TENSOR_END = BY_NAME["tensor_seq_end"].address + 1  # exclusive


def _check_table() -> None:
    used: dict[int, str] = {}
    for r in REGISTERS:
        for a in range(r.address, r.address + r.count):
            if a in used:
                raise AssertionError(f"register {a} used by {used[a]} and {r.name}")
            used[a] = r.name
    assert IMAGE_SIZE <= 125, "the whole image must be readable with one FC3/FC4 request"
    assert HANDSHAKE_START >= SNAPSHOT_END, "the handshake block lies past the snapshot"
    assert TENSOR_END - TENSOR_START <= 125 and TENSOR_START >= WRITABLE_END, "the tensor block: one request, apart"


_check_table()


# --- encoding ----------------------------------------------------------------


def encode_value(kind: str, value: Any, word_order: str) -> list[int]:
    """Registers for one value (None → NaN for floats, 0 for integers)."""
    if kind in ("uint16", "bits16"):
        return [int(value or 0) & 0xFFFF]
    if kind == "uint32":
        return to_registers(int(value or 0) & 0xFFFFFFFF, "uint32", word_order)
    if kind == "float32":
        v = float("nan") if value is None else float(value)
        # float32 rounding of a finite float64 beyond ±3.4e38 gives inf, which the PLC sees as such
        return to_registers(v, "float32", word_order)
    if kind == "uuid":
        b = uuidlib.UUID(str(value)).bytes if value else bytes(16)
        return list(struct.unpack(">8H", b))
    if kind == "ascii20":
        return encode_ascii(value or "", PART_ID_CHARS)
    raise ValueError(f"unknown register kind {kind!r}")


def encode_ascii(text: str, chars: int) -> list[int]:
    """ASCII text in chars/2 registers: 2 characters each, the first in the high byte, NUL-padded."""
    b = text.encode("ascii")[:chars].ljust(chars, b"\0")
    return list(struct.unpack(f">{chars // 2}H", b))


def decode_ascii(words: Sequence[int]) -> str:
    """The text of an ASCII register block (NULs and trailing blanks dropped; non-ASCII bytes as '?')."""
    b = struct.pack(f">{len(words)}H", *(int(w) & 0xFFFF for w in words))
    return b.replace(b"\0", b"").decode("ascii", errors="replace").replace("\ufffd", "?").strip()


def decode_value(kind: str, words: Sequence[int], word_order: str) -> Any:
    if kind in ("uint16", "bits16"):
        return int(words[0])
    if kind in ("uint32", "float32"):
        return from_registers(words, kind, word_order)
    if kind == "uuid":
        b = struct.pack(">8H", *words[:8])
        return None if b == bytes(16) else str(uuidlib.UUID(bytes=b))
    if kind == "ascii20":
        return decode_ascii(words[:PART_ID_CHARS // 2])
    raise ValueError(f"unknown register kind {kind!r}")


def _snapshot_values(payload: Mapping[str, Any] | None) -> dict[str, Any]:
    if payload is None:
        return {r.source: None for r in REGISTERS if r.area == "snapshot"} | {"seq": 0}
    flags = flag_bits(payload.get("flags") or ())
    return {
        "seq": modbus_seq(int(payload["seq"])),
        "finished_at": int(math.floor(float(payload["timestamp"]))),
        "J": payload.get("J"), "J_std": payload.get("J_std"),
        "omega_n": payload.get("omega_n"), "omega_n_std": payload.get("omega_n_std"),
        "damping_ratio": payload.get("damping_ratio"), "damping_ratio_std": payload.get("damping_ratio_std"),
        "residual_rms_after": payload.get("residual_rms_after"),
        "residual_rms_before": payload.get("residual_rms_before"),
        "noise_floor": payload.get("noise_floor"),
        "J_object": payload.get("J_object"),
        "J_U": payload.get("J_U"), "J_object_U": payload.get("J_object_U"),
        "flags": flags & 0xFFFF,
        "flags_high": flags >> 16,
        "effects": effect_bits(payload.get("effects") or ()),
        "uuid": payload.get("uuid"),
        **_part_values(payload),
    }


def _part_values(payload: Mapping[str, Any]) -> dict[str, Any]:
    """The part/verdict registers from the payload's part keys (service.publish.payload.PART_KEYS)."""
    release = payload.get("release") or {}
    part = payload.get("part") or {}
    recipe = payload.get("recipe") or {}
    return {
        "verdict": VERDICT_CODES.get(payload.get("verdict") or "", 0),
        "release_verdict": VERDICT_CODES.get(release.get("verdict") or "", 0),
        "release_index": release.get("index") or 0, "releases": release.get("of") or 0,
        "recipe_number": recipe.get("number") or 0,
        "part_value": part.get("mean"), "part_U": part.get("U"),
        "part_id": payload.get("part_id") or "",
    }


@dataclass(frozen=True)
class LiveStatus:
    """The live part of the image (not protected by the snapshot protocol)."""

    state: str | None = "STARTING"
    busy: bool = False
    fault: bool = False
    mqtt_connected: bool = False
    simulated: bool = False
    outbox_pending: int = 0
    started: int = 0
    recipe: int = 0          # active recipe number (0: none)
    releases_done: int = 0   # releases of the part in progress
    set_step: int = 0        # tensor set: the step to measure now (1-based; 0: no set)
    set_steps: int = 0       # tensor set: orientations in the plan
    set_orientation: int = 0  # tensor set: number of the orientation to mount now (1-based; 0: none)
    calibration_due: bool = False   # the rig's calibration is past its validity period
    store_unwritable: bool = False  # the result store cannot be written: measurements are refused

    def status_bits(self, result_valid: bool, verdict: str | None = None) -> int:
        """The status bits; ``verdict``: the snapshot's part verdict (sets part_ok / part_nok / part_invalid)."""
        bits = {
            "busy": self.busy, "result_valid": result_valid, "fault": self.fault,
            "mqtt_connected": self.mqtt_connected, "simulated": self.simulated,
            "outbox_pending": self.outbox_pending > 0,
            "part_ok": verdict == "OK", "part_nok": verdict == "NOK", "part_invalid": verdict == "INVALID",
        }
        return sum(1 << STATUS_BITS[k] for k, v in bits.items() if v)


def encode_snapshot(payload: Mapping[str, Any] | None, word_order: str = "big") -> list[int]:
    """Registers SNAPSHOT_START … SNAPSHOT_END-1 for a result payload (None: no result yet)."""
    _check_order(word_order)
    values = _snapshot_values(payload)
    out = [0] * (SNAPSHOT_END - SNAPSHOT_START)
    for r in REGISTERS:
        if r.area != "snapshot":
            continue
        words = encode_value(r.kind, values[r.source], word_order)
        out[r.address - SNAPSHOT_START: r.address - SNAPSHOT_START + r.count] = words
    return out


def encode_live(live: LiveStatus, result_valid: bool, word_order: str = "big", verdict: str | None = None) -> list[int]:
    """Registers LIVE_START … SNAPSHOT_START-1 (verdict: the snapshot's part verdict, for the status bits)."""
    _check_order(word_order)
    values = {
        "constant": MAP_VERSION, "state": state_code(live.state), "status": live.status_bits(result_valid, verdict),
        "started": live.started & 0xFFFF, "outbox_pending": min(int(live.outbox_pending), 0xFFFF),
        "recipe": live.recipe & 0xFFFF, "releases_done": min(int(live.releases_done), 0xFFFF),
        "set_step": live.set_step & 0xFFFF, "set_steps": live.set_steps & 0xFFFF,
        "set_orientation": live.set_orientation & 0xFFFF,
    }
    out = [0] * (SNAPSHOT_START - LIVE_START)
    for r in REGISTERS:
        if r.area == "live":
            out[r.address - LIVE_START: r.address - LIVE_START + r.count] = encode_value(r.kind, values[r.source], word_order)
    return out


def encode_tensor(tensor: Mapping[str, Any] | None, seq: int, word_order: str = "big") -> list[int]:
    """Registers TENSOR_START … TENSOR_END-1 for a tensor result (``TensorResult.to_dict()``; None: none yet)."""
    _check_order(word_order)
    values: dict[str, Any] = {"tensor_seq": modbus_seq(seq) if tensor is not None else 0}
    if tensor is not None:
        values |= {c: tensor["components"][c] for c in TENSOR_COMPONENTS}
        values |= {f"{c}_U": tensor["tensor_U"][c] for c in TENSOR_COMPONENTS}
        for i in range(3):
            values[f"I{i + 1}"] = tensor["principal_moments"][i]
            values[f"I{i + 1}_U"] = tensor["principal_moments_U"][i]
        values["tensor_flags"] = flag_bits(tensor.get("flags") or ()) >> 16
    out = [0] * (TENSOR_END - TENSOR_START)
    for r in REGISTERS:
        if r.area == "tensor":
            out[r.address - TENSOR_START: r.address - TENSOR_START + r.count] = encode_value(
                r.kind, values.get(r.source), word_order)
    return out


@dataclass(frozen=True)
class Handshake:
    """The values of the handshake block (registers HANDSHAKE_START … HANDSHAKE_END-1)."""

    plc_status: int = 0
    error_code: int = 0
    heartbeat: int = 0
    results_queued: int = 0
    overrun_count: int = 0
    command_echo: int = 0
    command_status: int = 0
    command_reason: int = 0
    command_count: int = 0


def assemble_image(live: Sequence[int], snapshot: Sequence[int], handshake: Sequence[int]) -> tuple[int, ...]:
    """Registers 0 … IMAGE_SIZE-1 from the three blocks (the addresses between them read as 0)."""
    gap = [0] * (HANDSHAKE_START - SNAPSHOT_END)
    return (*live, *snapshot, *gap, *handshake)


def plc_status_bits(**bits: bool) -> int:
    """Register `plc_status` from its bits by name (PLC_STATUS_BITS)."""
    return sum(1 << PLC_STATUS_BITS[k] for k, v in bits.items() if v)


def error_code(live: LiveStatus, *, plc_heartbeat_lost: bool, overrun: bool) -> int:
    """Register `error_code`: the highest-priority cause present (ERROR_CODES, lowest code first)."""
    causes = {"fault": live.fault, "store_unwritable": live.store_unwritable,
              "plc_heartbeat_lost": plc_heartbeat_lost, "result_buffer_overrun": overrun}
    return next((ERROR_CODE_BY_NAME[name] for name, present in causes.items() if present), 0)


def encode_handshake(h: Handshake) -> list[int]:
    """Registers HANDSHAKE_START … HANDSHAKE_END-1 (all uint16/bits16: no word order)."""
    out = [0] * (HANDSHAKE_END - HANDSHAKE_START)
    for r in REGISTERS:
        if r.area == "handshake":
            out[r.address - HANDSHAKE_START] = min(int(getattr(h, r.source)), 0xFFFF) if r.source in (
                "overrun_count",) else int(getattr(h, r.source)) & 0xFFFF
    return out


def decode_image(words: Sequence[int], word_order: str = "big", start: int = 0) -> dict[str, Any]:
    """Named values from registers read at ``start`` (any span; registers outside it are left out)."""
    _check_order(word_order)
    out: dict[str, Any] = {}
    end = start + len(words)
    for r in REGISTERS:
        if r.address >= start and r.address + r.count <= end:
            out[r.name] = decode_value(r.kind, words[r.address - start: r.address - start + r.count], word_order)
    return out


def _check_order(word_order: str) -> None:
    check_word_order(word_order)


# --- the reference client side of the snapshot protocol -----------------------


def read_snapshot(read: Callable[[int, int], Sequence[int]], word_order: str = "big", attempts: int = 5,
                  chunk: int | None = None) -> dict[str, Any] | None:
    """Read a consistent result snapshot the way docs/modbus.md tells a PLC to.

    read(address, count) returns ``count`` input registers. With ``chunk`` the
    snapshot is read in several requests (as a PLC limited to short reads
    would): `seq` first, then the body, and the snapshot is accepted only when
    `seq` and `seq_end` read afterwards both equal the first `seq`. Returns
    None when no consistent snapshot was obtained in ``attempts`` tries.
    """
    n = SNAPSHOT_END - SNAPSHOT_START
    for _ in range(attempts):
        if chunk is None:
            words = list(read(SNAPSHOT_START, n))
            seq_again = words[-1]
        else:
            seq_first = read(SNAPSHOT_START, 1)[0]
            words = [seq_first]
            addr = SNAPSHOT_START + 1
            while addr < SNAPSHOT_END:
                k = min(chunk, SNAPSHOT_END - addr)
                words += list(read(addr, k))
                addr += k
            seq_again = read(SNAPSHOT_START, 1)[0]
            if seq_again != words[0]:
                continue
        if words[0] == words[-1] == seq_again:
            return decode_image(words, word_order, start=SNAPSHOT_START)
    return None


# --- documentation -------------------------------------------------------------


def _handshake_markdown() -> list[str]:
    """The PLC handshake: status word, error codes, commands, the result queue, ST pseudo-code for both modes."""
    a = {name: addr for name, (addr, _) in WRITABLE.items()}
    b = BY_NAME
    L: list[str] = [f"## PLC handshake (registers {HANDSHAKE_START}–{HANDSHAKE_END - 1}, holding registers "
                    f"{a['command']}–{a['plc_heartbeat']})", ""]
    L.append(f"Registers {HANDSHAKE_START}–{HANDSHAKE_END - 1} are live, like 0–9, at a fixed address past the "
             f"snapshot, so that one request for registers 0–{IMAGE_SIZE - 1} reads everything.")
    L.append("")
    L.append("### Status word (register `plc_status`)")
    L.append("")
    L.append("| bit | name | set while |")
    L.append("|---:|---|---|")
    meaning = {
        "ready": "the appliance is IDLE: a trigger is accepted now",
        "busy": "a measurement runs (from ARMED until the result is published)",
        "result_valid": "the result block shows a result the PLC has not acknowledged (mode `latest`: any result "
                        "until acknowledged)",
        "result_buffer_overrun": "a result found the queue full (mode `ack`); `overrun_count` says how many; "
                                 "cleared by command 3 (acknowledge fault)",
        "error": "`error_code` is not 0",
        "calibration_due": "the rig's calibration is past its validity period (the result flag calibration_due "
                           "is set on every result meanwhile)",
        "not_decidable": "the shown result's verdict cannot decide: INVALID, or inside the guard band's uncertainty "
                         "range (ISO 14253-1)",
        "trigger_ack": "a trigger written to `command` was accepted; cleared when the PLC writes `command` again "
                       "(0 to take its hand off)",
        "plc_heartbeat_lost": "the PLC's heartbeat register did not change for `[modbus] plc_heartbeat_timeout`",
    }
    for name, bit in PLC_STATUS_BITS.items():
        L.append(f"| {bit} | `{name}` | {meaning[name]} |")
    L.append("")
    L.append("### Error codes (register `error_code`)")
    L.append("")
    L.append("| code | name | meaning |")
    L.append("|---:|---|---|")
    for code, (name, words) in ERROR_CODES.items():
        L.append(f"| {code} | `{name}` | {words} |")
    L.append("")
    L.append("When several causes are present the lowest code above 0 is shown.")
    L.append("")
    L.append("### Heartbeats")
    L.append("")
    L.append(f"`heartbeat` (register {b['heartbeat'].address}) is incremented every {HEARTBEAT_PERIOD:g} s by the "
             "appliance's main loop, the loop that runs the measurements: when it stops changing for a few "
             "seconds the appliance hangs, whatever the Modbus connection says. The PLC's own heartbeat goes the "
             f"other way: with `[modbus] plc_heartbeat_timeout` > 0 the PLC changes register {a['plc_heartbeat']} "
             "(any new value, e.g. a counter) more often than that; its silence raises `plc_heartbeat_lost` (status "
             "bit 8, error code 3), the log line, the systemd status and the health page say so, and it clears "
             "itself when the value changes again.")
    L.append("")
    L.append("### Commands (holding registers `command`, `command_parameter`)")
    L.append("")
    L.append("| code | command | does |")
    L.append("|---:|---|---|")
    does = {"trigger": "start one measurement (as coil 0 or the push button)",
            "abort": "abort the running measurement, or acknowledge a FAULT (as coil 1)",
            "acknowledge_fault": "acknowledge a FAULT and the result_buffer_overrun bit",
            "select_recipe": "make recipe number `command_parameter` active (0: none; as register recipe_select)"}
    for code, name in COMMANDS.items():
        L.append(f"| {code} | `{name}` | {does[name]} |")
    L.append("")
    L.append("The outcome: `command_echo` = the code, `command_status` = "
             + ", ".join(f"{c} {n}" for n, c in COMMAND_STATUS.items())
             + ", `command_reason` = why (table below), and `command_count` increments with each such change. "
             "A trigger goes accepted → done (its result is stored and queued) or failed (FAULT or aborted); the "
             "other commands go straight to done or refused.")
    L.append("")
    L.append("| reason | name | meaning |")
    L.append("|---:|---|---|")
    L.append("| 0 | – | not refused |")
    for name, r in REASONS.items():
        L.append(f"| {r.code} | `{name}` | {r.words} |")
    L.append("")
    L.append("The same reasons, by name, are in the MQTT command replies (docs/service.md).")
    L.append("")
    L.append("### The result queue (`[modbus] result_handshake`)")
    L.append("")
    L.append(f"`\"latest\"` (default, the map of versions before 10): the block {SNAPSHOT_START}–{SNAPSHOT_END - 1} "
             "shows the latest result; a "
             "result the PLC has not read yet is replaced by the next. `\"ack\"`: every stored result is queued "
             "(at most `[modbus] queue_depth`, default 8); the block shows the oldest one not yet acknowledged, "
             f"`results_queued` (register {b['results_queued'].address}) counts them. The PLC acknowledges it by "
             f"writing its `seq` to `result_ack` (register {a['result_ack']}): the next one is swapped in, or, "
             "when none waits, `result_valid` clears and the block keeps the acknowledged values. A result that "
             "finds the queue full is not queued: `overrun_count` counts it and `result_buffer_overrun` is set, so "
             "a loss is always visible (the result itself is stored and sent over MQTT). The appliance keeps "
             "the sequence number of the last acknowledged result in its state directory: after a restart the "
             "results stored since are queued again (the newest `queue_depth` of them; the PLC recognises a "
             "result it has seen by its `seq` and `uuid`).")
    L.append("")
    L.append("### PLC program, mode ack (IEC 61131-3 structured text, pseudo-code)")
    L.append("")
    L.append("```iecst")
    L.append(f"(* every scan: read registers 0..{IMAGE_SIZE - 1} in one FC 4 request into Img *)")
    L.append("CASE Step OF")
    L.append("  0: (* once per part type *)")
    L.append(f"     WriteRegs(addr := {a['command']}, values := [4, RecipeNo]);   (* select_recipe *)")
    L.append("     Step := 10;")
    L.append(f"  10: IF Img.plc_status.{PLC_STATUS_BITS['ready']} THEN  (* ready *)")
    L.append(f"        WriteRegs(addr := {a['part_id']}, values := PartIdWords);       (* 10 registers, ASCII *)")
    L.append("        LastCount := Img.command_count;")
    L.append(f"        WriteRegs(addr := {a['command']}, values := [1, 0]);          (* trigger *)")
    L.append("        Step := 20;")
    L.append("      END_IF;")
    L.append("  20: IF Img.command_count <> LastCount AND Img.command_echo = 1 THEN")
    L.append("        IF Img.command_status = 1 (* accepted *) THEN Step := 30;")
    L.append("        ELSE Reason := Img.command_reason; Step := 900; END_IF;")
    L.append(f"        WriteReg(addr := {a['command']}, value := 0);                 (* hand off: trigger_ack clears *)")
    L.append("      END_IF;")
    L.append(f"  30: IF Img.plc_status.{PLC_STATUS_BITS['result_valid']} THEN      (* result_valid *)")
    L.append(f"        Result := Img.snapshot;                              (* registers {SNAPSHOT_START}..{SNAPSHOT_END - 1} "
             "of the same read *)")
    L.append(f"        WriteReg(addr := {a['result_ack']}, value := Img.seq);         (* acknowledge it *)")
    L.append("        IF Result.release_index < Result.releases THEN Step := 10; ELSE Step := 40; END_IF;")
    L.append("      END_IF;")
    L.append("  40: (* latch Result.verdict: 1 OK, 2 NOK, 3 INVALID; not_decidable = measure again *)")
    L.append("      Step := 10;")
    L.append("  900: (* show Reason; busy: wait and retry; fault: acknowledge with command 3 *)")
    L.append("END_CASE;")
    L.append(f"IF Img.plc_status.{PLC_STATUS_BITS['result_buffer_overrun']} THEN Alarm(Img.overrun_count); END_IF;")
    L.append("IF Img.heartbeat = LastHeartbeat FOR 3 s THEN Alarm('appliance hangs'); END_IF;")
    L.append(f"WriteReg(addr := {a['plc_heartbeat']}, value := MyCounter);         (* every second, if the watchdog is on *)")
    L.append("```")
    L.append("")
    L.append("### PLC program, mode latest (no acknowledgement)")
    L.append("")
    L.append("```iecst")
    L.append("(* trigger with coil 0 or command 1 as above; then: *)")
    L.append(f"S1 := ReadReg({b['seq'].address});")
    L.append("IF S1 <> 0 AND S1 <> LastSeq THEN")
    L.append(f"  Body := ReadRegs({SNAPSHOT_START + 1}, {SNAPSHOT_END - SNAPSHOT_START - 1});   (* in parts if the PLC must *)")
    L.append(f"  S2 := ReadReg({b['seq'].address});")
    L.append("  IF S1 = S2 AND S2 = Body.seq_end THEN LastSeq := S1; (* use Body *) END_IF;  (* else: read again *)")
    L.append("END_IF;")
    L.append("```")
    L.append("")
    L.append("A result stored while the PLC did not look is replaced by the next in this mode; use mode ack when "
             "every result must reach the PLC.")
    L.append("")
    return L


def markdown() -> str:
    """docs/modbus.md, generated from the tables above (`moi modbus-map`)."""
    L: list[str] = []
    L.append("# Modbus register map (PLC interface)")
    L.append("")
    L.append("<!-- GENERATED by `moi modbus-map > docs/modbus.md` from service/publish/modbus/registers.py; do not edit by hand. -->")
    L.append("")
    L.append(f"Map version {MAP_VERSION}. The appliance is a Modbus server (slave): Modbus TCP by default, "
             "or Modbus RTU on a serial port (`[modbus] mode = \"rtu\"`). It answers the unit id set in "
             "`[modbus] unit_id` (default 1); on TCP other unit ids get exception 0x0B (gateway target failed "
             "to respond), on RTU they get no reply, as on any shared RS-485 line.")
    L.append("")
    L.append("Addresses are 0-based protocol addresses; tools that number from 1 (3x0001, 4x0001) add 1. "
             "Registers are 16 bit, big-endian within the register. 32-bit values (float32 IEEE 754 and uint32) "
             "span two registers; their word order is set by `[modbus] word_order`: `\"big\"` (default, high word "
             "first, ABCD) or `\"little\"` (low word first, CDAB). NaN marks an unknown value (e.g. J on a rig "
             "without k or m·S).")
    L.append("")
    L.append("## Input registers (FC 4), also readable as holding registers (FC 3)")
    L.append("")
    L.append("The same image is served by FC 4 and FC 3, so PLCs that only read holding registers work too. "
             "Every register of the image is read-only: FC 6/16/22/23 get exception 0x02 (illegal data address). "
             "Unlisted addresses inside 0…" f"{IMAGE_SIZE - 1} read as 0; addresses beyond get exception 0x02 "
             f"(except the writable holding registers {WRITABLE_START}–{WRITABLE_END - 1} below).")
    L.append("")
    L.append("| address | registers | name | type | unit | meaning |")
    L.append("|---:|---:|---|---|---|---|")
    for r in REGISTERS:
        span = f"{r.address}" if r.count == 1 else f"{r.address}–{r.address + r.count - 1}"
        L.append(f"| {span} | {r.count} | `{r.name}` | {r.kind} | {r.unit} | {r.description} |")
    L.append("")
    L.append(f"Registers {LIVE_START}–{SNAPSHOT_START - 1} are live status; registers {SNAPSHOT_START}–"
             f"{SNAPSHOT_END - 1} are the result snapshot of the latest successful measurement; registers "
             f"{TENSOR_START}–{TENSOR_END - 1} are the inertia tensor of the latest completed tensor set (a recipe "
             "with a [tensor] plan, docs/tensor.md), read as one block (one request) or with the snapshot "
             "protocol below on `tensor_seq` / `tensor_seq_end`. Addresses between the blocks get exception 0x02.")
    L.append("")
    L.append("## Writable holding registers (FC 6 / FC 16 write, FC 3 read back)")
    L.append("")
    L.append("| address | registers | name | meaning |")
    L.append("|---:|---:|---|---|")
    wmeaning = {
        "part_id": f"the part's serial number, up to {PART_ID_CHARS} ASCII characters, 2 per register (first character "
                   "in the high byte), padded with NUL (0); write it before setting the trigger coil. It is stored "
                   "with the measurement and echoed in `part_id` of the snapshot and in every MQTT payload",
        "recipe_select": "the number of the recipe (part type) to make active; 0: none. An unknown number gets "
                         "exception 0x03 (illegal data value). The active recipe reads back here and in `recipe`",
        "command": "a command code (table below); its outcome shows in `command_echo`, `command_status`, "
                   "`command_reason` and `command_count`. Write 0 to take the hand off (clears `trigger_ack`). "
                   "An unknown code gets 0x03 and does nothing. Not refused while a measurement runs: the "
                   "appliance answers busy in `command_reason` instead",
        "command_parameter": "the command's parameter, written with `command` in one FC 16 (select_recipe: the "
                             "recipe number, 0: none; an unknown number gets 0x03)",
        "result_ack": "acknowledge the result shown: write its `seq`. Any other value, or an acknowledgement "
                      "when none is waiting, gets 0x03 and changes nothing",
        "plc_heartbeat": "a counter the PLC changes at least every `[modbus] plc_heartbeat_timeout` seconds; "
                         "when it stops, `plc_heartbeat_lost` is raised (status bit, error code, health page)",
    }
    for name, (a, n) in WRITABLE.items():
        span = f"{a}" if n == 1 else f"{a}–{a + n - 1}"
        L.append(f"| {span} | {n} | `{name}` | {wmeaning[name]} |")
    L.append("")
    L.append("These are the only writable registers. A write to the part ID or recipe_select while a measurement "
             "runs (from the trigger until the result is published) gets exception 0x06 (server device busy): the "
             "part being measured cannot change. A part ID with bytes outside printable ASCII gets 0x03. Reading them with FC 3 gives "
             "the part ID and recipe now in force (also when set over MQTT). Other functions that would write "
             "them, FC 22 (mask write) and FC 23 (read/write multiple registers), get exception 0x01 (illegal "
             "function): a write is applied or refused, never acknowledged and dropped.")
    L.append("")
    L.append("## Verdicts (registers `verdict`, `release_verdict`; status bits 6–8)")
    L.append("")
    L.append("| code | verdict | meaning |")
    L.append("|---:|---|---|")
    L.append("| 0 | – | no verdict: the part is not complete yet, or no recipe is active |")
    vmeaning = {"OK": "conformance proven: the part value with its expanded uncertainty U lies inside the "
                      "tolerance (guard band, ISO 14253-1; the recipe's decision rule)",
                "NOK": "nonconformance, or conformance not proven (in the uncertainty range)",
                "INVALID": "the result cannot be trusted (a flag the recipe names, too large an uncertainty, too few "
                           "swings, releases that disagree, too few usable releases): measure the part again"}
    for name, code in VERDICT_CODES.items():
        L.append(f"| {code} | {name} | {vmeaning[name]} |")
    L.append("")
    L.append("A recipe asks for N releases per part: the appliance counts the releases of the same part ID and "
             "recipe; `release_index` of `releases` tells where the part stands, `part_releases_done` (live) too. "
             "`verdict` is set on the snapshot of the release that completes the part, with `part_value` (mean "
             "of the usable releases) and `part_U`; the status bits `part_ok`, `part_nok`, `part_invalid` (also "
             "discrete inputs 6–8) repeat it until the next result.")
    L.append("")
    L.append("## Coils (FC 1 read, FC 5 / FC 15 write)")
    L.append("")
    L.append("| address | name | write 1 means |")
    L.append("|---:|---|---|")
    meaning = {
        "trigger": "start one measurement (ignored while one runs, exactly as a button press); the coil reads back 0. "
                   "`measurements_started` increments when the measurement starts",
        "abort": "abort the running measurement (solenoid off, no result), or acknowledge a FAULT (FAULT is latched "
                 "until then; a trigger in FAULT is ignored); reads back 0",
        "set_redo": "tensor set (a recipe with a [tensor] plan): the releases of the current orientation (or, when "
                    "it has none yet, of the previous one) no longer count; measure it again. Refused while a "
                    "measurement runs; reads back 0",
        "set_skip": "tensor set: skip the current orientation (the tensor is computed without it, flag "
                    "orientation_excluded); reads back 0",
        "set_abort": "tensor set: abort the set; the releases measured so far stay stored, the set is stored as "
                     "aborted; reads back 0",
    }
    for name, a in COILS.items():
        L.append(f"| {a} | `{name}` | {meaning[name]} |")
    L.append("")
    L.append("Only these coils are writable. Writing 0 to them does nothing; any other write anywhere on the "
             "device, but the part ID and recipe_select registers, gets exception 0x02 (illegal data address). "
             "A single-coil write (FC 5) carries 0xFF00 or 0x0000, any other value gets exception 0x03 (illegal "
             "data value); the reply echoes the request.")
    L.append("")
    L.append("## Discrete inputs (FC 2)")
    L.append("")
    L.append("| address | name |")
    L.append("|---:|---|")
    for name, b in STATUS_BITS.items():
        L.append(f"| {b} | `{name}` |")
    L.append("")
    L.append("They repeat the bits of the `status` register.")
    L.append("")
    L.append("## Quality flags (register `flags`)")
    L.append("")
    L.append("| bit | flag | meaning |")
    L.append("|---:|---|---|")
    for name, b in FLAG_BITS.items():
        L.append(f"| {b} | `{name}` | {F.describe(name)} |")
    L.append(f"| {FLAG_OTHER_BIT} | any other flag | see the MQTT result's `flags` list for its name |")
    L.append("")
    L += _handshake_markdown()
    L.append("## Consistent-snapshot protocol")
    L.append("")
    L.append(f"The result snapshot (registers {SNAPSHOT_START}–{SNAPSHOT_END - 1}) is replaced as one unit: the "
             "server builds the complete new register image and swaps it in between two requests, so a single "
             f"FC 3/FC 4 request for registers {SNAPSHOT_START}–{SNAPSHOT_END - 1} (count "
             f"{SNAPSHOT_END - SNAPSHOT_START}) always returns one measurement: `seq` (first register) equals "
             "`seq_end` (last register). A new result is visible over Modbus only after it is stored in the "
             "result database, i.e. at the same moment it enters the MQTT outbox.")
    L.append("")
    L.append("A PLC that must split the read into several requests uses the sequence counter:")
    L.append("")
    L.append(f"1. read `seq` (register {SNAPSHOT_START}) → S1; if S1 = 0 there is no result yet;")
    L.append(f"2. read the body (registers {SNAPSHOT_START + 1}–{SNAPSHOT_END - 1}) in as many requests as needed;")
    L.append("3. read `seq` again → S2;")
    L.append("4. accept the values only if S1 = S2 = `seq_end`; otherwise a new result arrived meanwhile: start again.")
    L.append("")
    L.append("A result takes far longer than a PLC scan to produce (a swing lasts seconds), so the retry "
             "terminates at once. `seq` numbers every measurement the appliance stores (failed and aborted ones "
             "too, so it can jump by more than 1); a change of `seq` is the PLC's \"new result\" event. The same counter is `seq` in the MQTT result, and `uuid` "
             f"(registers {BY_NAME['uuid'].address}–{BY_NAME['uuid'].address + 7}) equals the MQTT `uuid`, so a PLC record can be joined with the broker's.")
    L.append("")
    L.append("## Typical PLC sequence")
    L.append("")
    L.append("1. once per part type: write the recipe number to `recipe_select` (register "
             f"{WRITABLE['recipe_select'][0]});")
    L.append("2. wait for `state` = 1 (IDLE);")
    L.append(f"3. write the part ID to registers {WRITABLE['part_id'][0]}–"
             f"{WRITABLE['part_id'][0] + WRITABLE['part_id'][1] - 1} (one FC 16);")
    L.append("4. write coil 0 (`trigger`) = 1, or let the operator press the button;")
    L.append("5. poll `state` / `seq`; when `seq` changes, read the snapshot as above;")
    L.append("6. if `release_index` < `releases`, go to 2 (re-latch and trigger the same part again);")
    L.append("7. latch `verdict` (or the status bits `part_ok` / `part_nok` / `part_invalid`); without a recipe, "
             "check `flags` = 0 (or decide which flags are acceptable) before using J.")
    L.append("")
    return "\n".join(L)
