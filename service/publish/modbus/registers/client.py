"""The reference client side of the snapshot protocol: a result read the way docs/modbus.md tells a PLC to."""

from __future__ import annotations

from typing import Any, Callable, Sequence

from .codec import decode_image
from .map import SNAPSHOT_END, SNAPSHOT_START


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
