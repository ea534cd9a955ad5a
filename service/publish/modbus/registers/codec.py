"""The Modbus register codec: the register words of a result payload, a live status, a tensor and the
handshake, and the named values of words read back (``decode_image``, the inverse a client uses: tests, bench,
``moi modbus-map --read``).

Everything the PLC reads is encoded here from the published result payload
(``service.publish.payload.result_payload``, itself built from
``IdentificationResult.to_dict()``), so the registers and the MQTT JSON
cannot disagree. The server (``service.publish.modbus.server``) only copies the
register image produced here.
"""

from __future__ import annotations

import math
import struct
import uuid as uuidlib
from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Sequence

from drivers.modbus_words import check_word_order, from_registers, to_registers
from measurement.flags import flag_bits
from service.core.live import LiveStatus
from service.parts.outcome import PartOutcome

from .map import (
    EFFECT_BITS,
    EFFECT_OTHER_BIT,
    ERROR_CODE_BY_NAME,
    HANDSHAKE_END,
    HANDSHAKE_START,
    LIVE_START,
    MAP_VERSION,
    PART_ID_CHARS,
    PLC_STATUS_BITS,
    REGISTERS,
    SNAPSHOT_END,
    SNAPSHOT_START,
    STATE_CODES,
    STATE_OTHER,
    STATUS_BITS,
    TENSOR_COMPONENTS,
    TENSOR_END,
    TENSOR_START,
    VERDICT_CODES,
)


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
    """The part/verdict registers from the payload's part keys (``PartOutcome``)."""
    o = PartOutcome.from_dict(payload)
    rel, part = o.release, o.part
    return {
        "verdict": VERDICT_CODES.get(o.verdict or "", 0),
        "release_verdict": VERDICT_CODES.get((rel.verdict if rel is not None else None) or "", 0),
        "release_index": rel.index if rel is not None else 0, "releases": rel.of if rel is not None else 0,
        "recipe_number": (o.recipe or {}).get("number") or 0,
        "part_value": part.value if part is not None else None, "part_U": part.U if part is not None else None,
        "part_id": o.part_id or "",
    }

def status_bits(live: LiveStatus, result_valid: bool, verdict: str | None = None) -> int:
    """Register `status` (and the discrete inputs) of a live status; ``verdict``: the snapshot's part verdict
    (sets part_ok / part_nok / part_invalid)."""
    bits = {
        "busy": live.busy, "result_valid": result_valid, "fault": live.fault,
        "mqtt_connected": live.mqtt_connected, "simulated": live.simulated,
        "outbox_pending": live.outbox_pending > 0,
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
        "constant": MAP_VERSION, "state": state_code(live.state), "status": status_bits(live, result_valid, verdict),
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
