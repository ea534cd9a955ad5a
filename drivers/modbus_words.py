"""32-bit values in two 16-bit Modbus registers, in either word order: pymodbus's own conversion.

"big" puts the high word first (ABCD), "little" the low word first (CDAB);
the bytes within a register are always big-endian, as Modbus defines them.
The encoder driver, the simulated encoder and the appliance's register map
all pack and unpack through here. pymodbus is imported on first use, so the
register map can be described (`moi modbus-map`) without loading it.
"""

from __future__ import annotations

from typing import Sequence

#: the two word orders of a 32-bit value in two registers
WORD_ORDERS = ("big", "little")

_TYPES = {"uint32": "UINT32", "float32": "FLOAT32"}


def _datatype(kind: str):
    from pymodbus.client.mixin import ModbusClientMixin

    try:
        return ModbusClientMixin, getattr(ModbusClientMixin.DATATYPE, _TYPES[kind])
    except KeyError:
        raise ValueError(f"unknown 32-bit register kind {kind!r}; expected one of {', '.join(_TYPES)}") from None


def check_word_order(word_order: str) -> str:
    if word_order not in WORD_ORDERS:
        raise ValueError(f"word order must be one of {WORD_ORDERS}, got {word_order!r}")
    return word_order


def to_registers(value: int | float, kind: str, word_order: str) -> list[int]:
    """The two registers of ``value`` as ``kind`` ("uint32" | "float32") in ``word_order``."""
    mixin, datatype = _datatype(kind)
    return mixin.convert_to_registers(value, datatype, check_word_order(word_order))


def from_registers(words: Sequence[int], kind: str, word_order: str) -> int | float:
    """The value of two registers read as ``kind`` ("uint32" | "float32") in ``word_order``."""
    mixin, datatype = _datatype(kind)
    return mixin.convert_from_registers(list(words[:2]), datatype, check_word_order(word_order))
