"""`docs/modbus.md`: the register map as a PLC programmer reads it, with the handshake in IEC 61131-3
structured text, generated from the map's tables (``moi modbus-map > docs/modbus.md``)."""

from __future__ import annotations

from measurement import flags as F
from service.publish.replies import REASONS

from .map import (
    BY_NAME,
    COIL_TABLE,
    COMMAND_STATUS,
    COMMAND_TABLE,
    ERROR_CODES,
    HANDSHAKE_END,
    HANDSHAKE_START,
    HEARTBEAT_PERIOD,
    IMAGE_SIZE,
    LIVE_START,
    MAP_VERSION,
    PLC_STATUS,
    PLC_STATUS_BITS,
    REGISTERS,
    SNAPSHOT_END,
    SNAPSHOT_START,
    STATUS_BITS,
    TENSOR_END,
    TENSOR_START,
    VERDICT_CODES,
    WRITABLE,
    WRITABLE_END,
    WRITABLE_REGISTERS,
    WRITABLE_START,
)


def _addresses() -> dict[str, int]:
    """The writable holding registers' addresses by name."""
    return {name: addr for name, (addr, _) in WRITABLE.items()}


def _handshake_intro() -> list[str]:
    """The handshake's registers, read with the image."""
    a = _addresses()
    L: list[str] = []
    L.append(f"## PLC handshake (registers {HANDSHAKE_START}–{HANDSHAKE_END - 1}, holding registers "
             f"{a['command']}–{a['plc_heartbeat']})")
    L.append("")
    L.append(f"Registers {HANDSHAKE_START}–{HANDSHAKE_END - 1} are live, like 0–9, at a fixed address past the "
             f"snapshot, so that one request for registers 0–{IMAGE_SIZE - 1} reads everything.")
    L.append("")
    return L


def _status_word() -> list[str]:
    """The status word's bits."""
    L: list[str] = []
    L.append("### Status word (register `plc_status`)")
    L.append("")
    L.append("| bit | name | set while |")
    L.append("|---:|---|---|")
    for name, (bit, meaning) in PLC_STATUS.items():
        L.append(f"| {bit} | `{name}` | {meaning} |")
    L.append("")
    return L


def _error_codes() -> list[str]:
    """The error codes."""
    L: list[str] = []
    L.append("### Error codes (register `error_code`)")
    L.append("")
    L.append("| code | name | meaning |")
    L.append("|---:|---|---|")
    for code, (name, words) in ERROR_CODES.items():
        L.append(f"| {code} | `{name}` | {words} |")
    L.append("")
    L.append("When several causes are present the lowest code above 0 is shown.")
    L.append("")
    return L


def _heartbeats() -> list[str]:
    """The appliance's heartbeat and the PLC's."""
    a = _addresses()
    b = BY_NAME
    L: list[str] = []
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
    return L


def _commands() -> list[str]:
    """The commands and their outcome, with the reasons of a refusal."""
    L: list[str] = []
    L.append("### Commands (holding registers `command`, `command_parameter`)")
    L.append("")
    L.append("| code | command | does |")
    L.append("|---:|---|---|")
    for code, (name, does) in COMMAND_TABLE.items():
        L.append(f"| {code} | `{name}` | {does} |")
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
    return L


def _result_queue() -> list[str]:
    """The two result handshakes (`[modbus] result_handshake`)."""
    a = _addresses()
    b = BY_NAME
    L: list[str] = []
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
    return L


def _plc_program_ack() -> list[str]:
    """The PLC program of mode ack, in structured text."""
    a = _addresses()
    L: list[str] = []
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
    L.append("  900: (* show Reason; busy: wait and retry; fault: acknowledge with command 3; "
             "calibration_due: call the quality engineer *)")
    L.append("END_CASE;")
    L.append(f"IF Img.plc_status.{PLC_STATUS_BITS['result_buffer_overrun']} THEN Alarm(Img.overrun_count); END_IF;")
    L.append("IF Img.heartbeat = LastHeartbeat FOR 3 s THEN Alarm('appliance hangs'); END_IF;")
    L.append(f"WriteReg(addr := {a['plc_heartbeat']}, value := MyCounter);         (* every second, if the watchdog is on *)")
    L.append("```")
    L.append("")
    return L


def _plc_program_latest() -> list[str]:
    """The PLC program of mode latest, in structured text."""
    b = BY_NAME
    L: list[str] = []
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


def _handshake_markdown() -> list[str]:
    """The PLC handshake: status word, error codes, commands, the result queue, ST pseudo-code for both modes."""
    return [line for section in (_handshake_intro, _status_word, _error_codes, _heartbeats,
                                 _commands, _result_queue, _plc_program_ack, _plc_program_latest) for line in section()]


def _preamble() -> list[str]:
    """The title, the map version, the server's unit id and how addresses and words are counted."""
    L: list[str] = []
    L.append("# Modbus register map (PLC interface)")
    L.append("")
    L.append("<!-- GENERATED by `moi modbus-map > docs/modbus.md` from service/publish/modbus/registers/; do not edit by hand. -->")
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
    return L


def _input_registers() -> list[str]:
    """The register image (FC 4 and FC 3)."""
    L: list[str] = []
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
    return L


def _writable_registers() -> list[str]:
    """The writable holding registers."""
    L: list[str] = []
    L.append("## Writable holding registers (FC 6 / FC 16 write, FC 3 read back)")
    L.append("")
    L.append("| address | registers | name | meaning |")
    L.append("|---:|---:|---|---|")
    for name, (a, n, meaning) in WRITABLE_REGISTERS.items():
        span = f"{a}" if n == 1 else f"{a}–{a + n - 1}"
        L.append(f"| {span} | {n} | `{name}` | {meaning} |")
    L.append("")
    L.append("These are the only writable registers. A write to the part ID or recipe_select while a measurement "
             "runs (from the trigger until the result is published) gets exception 0x06 (server device busy): the "
             "part being measured cannot change. A part ID with bytes outside printable ASCII gets 0x03. Reading them with FC 3 gives "
             "the part ID and recipe now in force (also when set over MQTT). Other functions that would write "
             "them, FC 22 (mask write) and FC 23 (read/write multiple registers), get exception 0x01 (illegal "
             "function): a write is applied or refused, never acknowledged and dropped.")
    L.append("")
    return L


def _verdicts() -> list[str]:
    """The verdict codes and how a part's releases are counted."""
    L: list[str] = []
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
    return L


def _coils() -> list[str]:
    """The command coils."""
    L: list[str] = []
    L.append("## Coils (FC 1 read, FC 5 / FC 15 write)")
    L.append("")
    L.append("| address | name | write 1 means |")
    L.append("|---:|---|---|")
    for name, (a, meaning) in COIL_TABLE.items():
        L.append(f"| {a} | `{name}` | {meaning} |")
    L.append("")
    L.append("Only these coils are writable. Writing 0 to them does nothing; any other write anywhere on the "
             "device, but the part ID and recipe_select registers, gets exception 0x02 (illegal data address). "
             "A single-coil write (FC 5) carries 0xFF00 or 0x0000, any other value gets exception 0x03 (illegal "
             "data value); the reply echoes the request.")
    L.append("")
    return L


def _discrete_inputs() -> list[str]:
    """The discrete inputs."""
    L: list[str] = []
    L.append("## Discrete inputs (FC 2)")
    L.append("")
    L.append("| address | name |")
    L.append("|---:|---|")
    for name, b in STATUS_BITS.items():
        L.append(f"| {b} | `{name}` |")
    L.append("")
    L.append("They repeat the bits of the `status` register.")
    L.append("")
    return L


def _quality_flags() -> list[str]:
    """The quality flags' bits."""
    L: list[str] = []
    L.append("## Quality flags (register `flags`)")
    L.append("")
    L.append("A **warning** is a condition that may move J beyond the uncertainty the result states (a recipe may")
    L.append("make it INVALID); **information** describes the record or its residual, and what it does to J is in")
    L.append("its u (by default it invalidates nothing).")
    L.append("")
    L.append("| bit | flag | grade | meaning |")
    L.append("|---:|---|---|---|")
    for name, b in F.FLAG_BITS.items():
        L.append(f"| {b} | `{name}` | {F.grade(name)} | {F.describe(name)} |")
    L.append(f"| {F.FLAG_OTHER_BIT} | any other flag | warning | see the MQTT result's `flags` list for its name |")
    L.append("")
    return L


def _snapshot_protocol() -> list[str]:
    """The consistent-snapshot protocol."""
    L: list[str] = []
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
    return L


def _typical_sequence() -> list[str]:
    """A PLC's sequence, step by step."""
    L: list[str] = []
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
    return L


def markdown() -> str:
    """docs/modbus.md, generated from the map's tables (`moi modbus-map`)."""
    sections = (_preamble, _input_registers, _writable_registers, _verdicts, _coils, _discrete_inputs, _quality_flags,
                _handshake_markdown, _snapshot_protocol, _typical_sequence)
    return "\n".join(line for section in sections for line in section())
