"""The Modbus register map, its codec, the reference client of its snapshot protocol and its documentation.

``map`` holds the tables (addresses, kinds, bits, codes, the writable registers and coils, with what each
means); ``codec`` turns a result payload, the live status, a tensor and the handshake into register words and
back; ``client`` reads a consistent snapshot as a PLC must; ``document`` writes `docs/modbus.md` from the
tables. The names below are the package's interface (``from service.publish.modbus import registers as R``).
"""

from __future__ import annotations

from drivers.modbus_words import WORD_ORDERS

from .client import read_snapshot
from .codec import (
    Handshake,
    assemble_image,
    decode_ascii,
    decode_image,
    decode_value,
    effect_bits,
    encode_ascii,
    encode_handshake,
    encode_live,
    encode_snapshot,
    encode_tensor,
    encode_value,
    error_code,
    modbus_seq,
    plc_status_bits,
    state_code,
    status_bits,
)
from .document import markdown
from .map import (
    BY_NAME,
    COIL_TABLE,
    COILS,
    COMMAND_CODES,
    COMMAND_STATUS,
    COMMAND_TABLE,
    COMMANDS,
    DAEMON_COMMAND,
    EFFECT_BITS,
    EFFECT_OTHER_BIT,
    ERROR_CODE_BY_NAME,
    ERROR_CODES,
    HANDSHAKE_END,
    HANDSHAKE_START,
    HEARTBEAT_PERIOD,
    IMAGE_SIZE,
    LIVE_START,
    MAP_VERSION,
    PART_ID_CHARS,
    PART_INPUTS,
    PLC_STATUS,
    PLC_STATUS_BITS,
    REGISTERS,
    SNAPSHOT_END,
    SNAPSHOT_START,
    STATE_CODES,
    STATE_OTHER,
    STATUS_BITS,
    TENSOR_COMPONENTS,
    TENSOR_END,
    TENSOR_FLAGS,
    TENSOR_START,
    VERDICT_CODES,
    WRITABLE,
    WRITABLE_END,
    WRITABLE_REGISTERS,
    WRITABLE_START,
    Register,
)

__all__ = [
    "BY_NAME", "COIL_TABLE", "COILS", "COMMAND_CODES", "COMMAND_STATUS", "COMMAND_TABLE", "COMMANDS",
    "DAEMON_COMMAND", "EFFECT_BITS", "EFFECT_OTHER_BIT", "ERROR_CODE_BY_NAME", "ERROR_CODES",
    "HANDSHAKE_END", "HANDSHAKE_START", "HEARTBEAT_PERIOD", "IMAGE_SIZE", "LIVE_START",
    "MAP_VERSION", "PART_ID_CHARS", "PART_INPUTS", "PLC_STATUS", "PLC_STATUS_BITS", "REGISTERS", "SNAPSHOT_END",
    "SNAPSHOT_START", "STATE_CODES", "STATE_OTHER", "STATUS_BITS", "TENSOR_COMPONENTS", "TENSOR_END",
    "TENSOR_FLAGS", "TENSOR_START", "VERDICT_CODES", "WORD_ORDERS", "WRITABLE", "WRITABLE_END",
    "WRITABLE_REGISTERS", "WRITABLE_START", "Handshake", "Register", "assemble_image", "decode_ascii",
    "decode_image", "decode_value", "effect_bits", "encode_ascii", "encode_handshake", "encode_live",
    "encode_snapshot", "encode_tensor", "encode_value", "error_code", "markdown",
    "modbus_seq", "plc_status_bits", "read_snapshot", "state_code", "status_bits",
]
