"""The Modbus register map: the tables a PLC programmer reads, from which the server serves, the codec encodes
and `docs/modbus.md` is generated.

Addresses are 0-based protocol addresses (the "PDU address"); PLC tools
that count from 1 (4x0001 / 3x0001 style) add 1.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from measurement import flags as F
from measurement.tensor import COMPONENTS
from service.core import vocabulary as V
from service.parts.recipes import PART_ID_LENGTH
from service.publish.replies import REASONS
from service.states import STATES

#: bumped whenever an address or an encoding of the map changes; what each version changed is in CHANGELOG.md
MAP_VERSION = 13


# --- enumerations ------------------------------------------------------------

#: sequencer/daemon state → code in register `state`
STATE_CODES: dict[str, int] = {name: s.code for name, s in STATES.items()}
STATE_OTHER = 255

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

#: bits of register `plc_status`, the handshake's status word (the bits integrators know from vision sensors):
#: name → (bit, set while)
PLC_STATUS: dict[str, tuple[int, str]] = {
    "ready": (0, "the appliance is IDLE: a trigger is accepted now (not while the calibration refuses it: "
                 "`calibration_due` set, a trigger answered with reason 12 calibration_due)"),
    "busy": (1, "a measurement runs (from ARMED until the result is published)"),
    "result_valid": (2, "the result block shows a result the PLC has not acknowledged (mode `latest`: any result "
                        "until acknowledged)"),
    "result_buffer_overrun": (3, "a result found the queue full (mode `ack`); `overrun_count` says how many; "
                                 "cleared by command 3 (acknowledge fault)"),
    "error": (4, "`error_code` is not 0"),
    "calibration_due": (5, "the rig's calibration is past its validity period, or its newest check standard "
                           "failed: a trigger is refused (reason 12), but for a check-standard recipe while the "
                           "calibration itself has not expired"),
    "not_decidable": (6, "the shown result's verdict cannot decide: INVALID, or inside the guard band's uncertainty "
                         "range (ISO 14253-1)"),
    "trigger_ack": (7, "a trigger written to `command` was accepted; cleared when the PLC writes `command` again "
                       "(0 to take its hand off)"),
    "plc_heartbeat_lost": (8, "the PLC's heartbeat register did not change for `[modbus] plc_heartbeat_timeout`"),
}
PLC_STATUS_BITS: dict[str, int] = {name: bit for name, (bit, _) in PLC_STATUS.items()}

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

#: register `command`: code → (name, what it does); the name is the daemon's command it queues
#: (``service.core.vocabulary``) but for select_recipe (DAEMON_COMMAND)
COMMAND_TABLE: dict[int, tuple[str, str]] = {
    1: (V.TRIGGER, "start one measurement (as coil 0 or the push button)"),
    2: (V.ABORT, "abort the running measurement, or acknowledge a FAULT (as coil 1)"),
    3: (V.ACKNOWLEDGE_FAULT, "acknowledge a FAULT and the result_buffer_overrun bit"),
    4: ("select_recipe", "make recipe number `command_parameter` active (0: none; as register recipe_select)"),
}
COMMANDS: dict[int, str] = {code: name for code, (name, _) in COMMAND_TABLE.items()}
#: the daemon's command a Modbus command queues where their names differ (its parameter is the data)
DAEMON_COMMAND: dict[str, str] = {"select_recipe": V.RECIPE}
COMMAND_CODES: dict[str, int] = {name: code for code, name in COMMANDS.items()}

#: register `command_status`
COMMAND_STATUS: dict[str, int] = {"none": 0, "accepted": 1, "refused": 2, "done": 3, "failed": 4}

#: the appliance increments `heartbeat` this often while its main loop runs, s
HEARTBEAT_PERIOD = 0.5

#: verdict → code in registers `verdict` and `release_verdict` (0: none yet / part not complete / no recipe)
VERDICT_CODES: dict[str, int] = {"OK": 1, "NOK": 2, "INVALID": 3}

#: characters of the part ID block (2 ASCII characters per register, first character in the high byte)
PART_ID_CHARS = PART_ID_LENGTH  # the recipes' rule; two characters per register

#: the only writable holding registers (FC 6 / FC 16), read back with FC 3: name → (address, count, meaning)
WRITABLE_REGISTERS: dict[str, tuple[int, int, str]] = {
    "part_id": (100, PART_ID_CHARS // 2,
                f"the part's serial number, up to {PART_ID_CHARS} ASCII characters, 2 per register (first character "
                "in the high byte), padded with NUL (0); write it before setting the trigger coil. It is stored "
                "with the measurement and echoed in `part_id` of the snapshot and in every MQTT payload"),
    "recipe_select": (110, 1,
                      "the number of the recipe (part type) to make active; 0: none. An unknown number gets "
                      "exception 0x03 (illegal data value). The active recipe reads back here and in `recipe`"),
    "command": (111, 1,
                "a command code (table below); its outcome shows in `command_echo`, `command_status`, "
                "`command_reason` and `command_count`. Write 0 to take the hand off (clears `trigger_ack`). "
                "An unknown code gets 0x03 and does nothing. Not refused while a measurement runs: the "
                "appliance answers busy in `command_reason` instead"),
    "command_parameter": (112, 1,
                          "the command's parameter, written with `command` in one FC 16 (select_recipe: the "
                          "recipe number, 0: none; an unknown number gets 0x03)"),
    "result_ack": (113, 1,
                   "acknowledge the result shown: write its `seq`. Any other value, or an acknowledgement "
                   "when none is waiting, gets 0x03 and changes nothing"),
    "plc_heartbeat": (114, 1,
                      "a counter the PLC changes at least every `[modbus] plc_heartbeat_timeout` seconds; "
                      "when it stops, `plc_heartbeat_lost` is raised (status bit, error code, health page)"),
}
WRITABLE: dict[str, tuple[int, int]] = {name: (a, n) for name, (a, n, _) in WRITABLE_REGISTERS.items()}
#: the writable registers that say which part is measured: refused while a measurement runs
PART_INPUTS = ("part_id", "recipe_select")
WRITABLE_START = min(a for a, _ in WRITABLE.values())
WRITABLE_END = max(a + n for a, n in WRITABLE.values())  # exclusive

#: coils (FC1 read, FC5/FC15 write), the only writable bits on the whole device: name (the daemon's command
#: a 1 queues, ``service.core.vocabulary``) → (address, what writing 1 means)
COIL_TABLE: dict[str, tuple[int, str]] = {
    V.TRIGGER: (0,
                "start one measurement (ignored while one runs, exactly as a button press, and refused while the "
                "calibration refuses it: `ready` clear, `calibration_due` set; command 1 says the reason); the coil "
                "reads back 0. `measurements_started` increments when the measurement starts"),
    V.ABORT: (1,
              "abort the running measurement (solenoid off, no result), or acknowledge a FAULT (FAULT is latched "
              "until then; a trigger in FAULT is ignored); reads back 0"),
    V.SET_REDO: (2,
                 "tensor set (a recipe with a [tensor] plan): the releases of the current orientation (or, when "
                 "it has none yet, of the previous one) no longer count; measure it again. Refused while a "
                 "measurement runs; reads back 0"),
    V.SET_SKIP: (3,
                 "tensor set: skip the current orientation (the tensor is computed without it, flag "
                 "orientation_excluded); reads back 0"),
    V.SET_ABORT: (4,
                  "tensor set: abort the set; the releases measured so far stay stored, the set is stored as "
                  "aborted; reads back 0"),
}
COILS: dict[str, int] = {name: address for name, (address, _) in COIL_TABLE.items()}


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


#: adds one register: area, address, name, kind, unit, source, description
_Add = Callable[[str, int, str, str, str, str, str], None]


def _table() -> tuple[Register, ...]:
    rows: list[Register] = []

    def add(area: str, address: int, name: str, kind: str, unit: str, source: str, description: str) -> None:
        rows.append(Register(name, address, kind, unit, description, source, area))

    for block in (_live_registers, _snapshot_registers, _handshake_registers, _tensor_registers):
        block(add)
    return tuple(rows)


def _live_registers(add: _Add) -> None:
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


def _snapshot_registers(add: _Add) -> None:
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
        "quality flags: " + ", ".join(f"bit {b} {n}" for n, b in F.FLAG_BITS.items() if b < 16)
        + f", bit {F.FLAG_OTHER_BIT} other")
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
        "more quality flags: " + ", ".join(f"bit {b - 16} {n}" for n, b in F.FLAG_BITS.items() if b >= 16))
    add("snapshot", 63, "J_U", "float32", "kg·m²", "J_U",
        "expanded uncertainty U of J from its uncertainty budget (coverage factor in the result, k = 2 unless "
        "few degrees of freedom call for more; NaN when J is unknown)")
    add("snapshot", 65, "J_object_U", "float32", "kg·m²", "J_object_U",
        "expanded uncertainty U of J_object, the k–I0 correlation of the calibration kept (NaN without a tare)")
    add("snapshot", 67, "seq_end", "uint16", "count", "seq", "copy of `seq`, the last register of the snapshot")


def _handshake_registers(add: _Add) -> None:
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


def _tensor_registers(add: _Add) -> None:
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
            f"bit {b - 16} {n}" for n, b in F.FLAG_BITS.items() if n in TENSOR_FLAGS))
    add("tensor", a + 38, "tensor_seq_end", "uint16", "count", "tensor_seq", "copy of `tensor_seq`, the block's last register")


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
