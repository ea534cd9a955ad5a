"""The rows of a SQLite table read straight from its leaf pages, for when the table's tree is damaged.

A table's rows live in the leaf pages of its b-tree; the root and inner pages only point to them.
When the root page of the results table is overwritten, SQLite reaches none of the rows although
every leaf page is intact. This module walks the file page by page and decodes every table-leaf
cell, following overflow chains, as the file format lays them out (SQLite's "Database File Format"
document, sections 1.3 B-tree pages, 1.6 overflow pages and 2.1 record format). SQLite's own
recovery (the CLI's ``.recover``) is not usable here: the Debian build the appliance ships with does
not carry the page virtual table it needs.

Only the main database file is read: run it on a checkpointed file (a salvage reads the file that was
moved aside; pages still in its write-ahead log are read by SQLite itself). The caller decides which
decoded records are rows of the table it wants (see ``salvage.salvage_store``): a leaf page carries no
table name.
"""

from __future__ import annotations

import mmap
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

_TABLE_LEAF = 0x0D


@dataclass(frozen=True)
class LeafRecord:
    """One cell of a table-leaf page: the row's rowid and its decoded columns (as stored, in order)."""

    page: int
    rowid: int
    values: tuple


def _varint(buf: bytes, i: int) -> tuple[int, int]:
    """SQLite's big-endian variable-length integer at ``buf[i]``: (value, index after it)."""
    v = 0
    for k in range(8):
        b = buf[i + k]
        v = (v << 7) | (b & 0x7F)
        if b < 0x80:
            return v, i + k + 1
    return (v << 8) | buf[i + 8], i + 9


def _value(serial: int, data: bytes, i: int) -> tuple[object, int]:
    if serial == 0:
        return None, i
    if 1 <= serial <= 6:
        n = (1, 2, 3, 4, 6, 8)[serial - 1]
        return int.from_bytes(data[i:i + n], "big", signed=True), i + n
    if serial == 7:
        return struct.unpack(">d", data[i:i + 8])[0], i + 8
    if serial in (8, 9):
        return serial - 8, i
    if serial >= 12:
        n = (serial - 12) // 2
        raw = data[i:i + n]
        if len(raw) != n:
            raise ValueError("record shorter than its header says")
        return (bytes(raw) if serial % 2 == 0 else raw.decode("utf-8")), i + n
    raise ValueError(f"reserved serial type {serial}")


def decode_record(payload: bytes) -> tuple:
    """The columns of one record (ValueError when it does not decode)."""
    size, i = _varint(payload, 0)
    serials = []
    while i < size:
        s, i = _varint(payload, i)
        serials.append(s)
    values = []
    j = size
    for s in serials:
        v, j = _value(s, payload, j)
        values.append(v)
    if j > len(payload):
        raise ValueError("record longer than its payload")
    return tuple(values)


class _File:
    def __init__(self, data: bytes | mmap.mmap) -> None:
        if data[:16] != b"SQLite format 3\x00":
            raise ValueError("not a SQLite database file (header damaged)")
        size = int.from_bytes(data[16:18], "big")
        self.page_size = 65536 if size == 1 else size
        self.usable = self.page_size - data[20]
        self.data = data
        self.pages = len(data) // self.page_size

    def page(self, n: int) -> bytes:
        return bytes(self.data[(n - 1) * self.page_size:n * self.page_size])

    def freelist(self) -> set[int]:
        """Pages on the free list (they may hold rows deleted long ago: never read as rows)."""
        free: set[int] = set()
        trunk = int.from_bytes(self.data[32:36], "big")
        while 0 < trunk <= self.pages and trunk not in free:
            free.add(trunk)
            p = self.page(trunk)
            count = int.from_bytes(p[4:8], "big")
            for k in range(min(count, (self.usable - 8) // 4)):
                free.add(int.from_bytes(p[8 + 4 * k:12 + 4 * k], "big"))
            trunk = int.from_bytes(p[0:4], "big")
        return free

    def payload(self, page: bytes, i: int, length: int) -> bytes:
        """A cell's payload starting at ``page[i]``, with its overflow chain."""
        u = self.usable
        most = u - 35
        if length <= most:
            return page[i:i + length]
        least = (u - 12) * 32 // 255 - 23
        local = least + (length - least) % (u - 4)
        if local > most:
            local = least
        parts = [page[i:i + local]]
        nxt = int.from_bytes(page[i + local:i + local + 4], "big")
        left = length - local
        seen: set[int] = set()
        while left > 0:
            if not 0 < nxt <= self.pages or nxt in seen:
                raise ValueError("overflow chain broken")
            seen.add(nxt)
            ov = self.page(nxt)
            take = min(left, u - 4)
            parts.append(ov[4:4 + take])
            left -= take
            nxt = int.from_bytes(ov[0:4], "big")
        return b"".join(parts)


def leaf_records(path: str | Path, wanted: Callable[[int], bool] = lambda rowid: True) -> Iterator[LeafRecord]:
    """Every record of every table-leaf page of the database file at ``path`` that decodes, of the rowids
    ``wanted`` accepts (asked before a cell's payload and its overflow chain are read).

    Cells that do not decode (a damaged page, a broken overflow chain) are skipped: this reads what
    is left, it does not judge it. The file is mapped, not read into memory (a store of traces may be
    larger than a device's memory). Raises ValueError when the file's header is gone."""
    with open(path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as data:
        yield from _records(_File(data), wanted)


def _records(f: "_File", wanted: Callable[[int], bool]) -> Iterator[LeafRecord]:
    free = f.freelist()
    for n in range(1, f.pages + 1):
        if n in free:
            continue
        page = f.page(n)
        start = 100 if n == 1 else 0
        if page[start] != _TABLE_LEAF:
            continue
        cells = int.from_bytes(page[start + 3:start + 5], "big")
        for c in range(cells):
            try:
                at = int.from_bytes(page[start + 8 + 2 * c:start + 10 + 2 * c], "big")
                if not start + 8 <= at < f.usable:
                    continue
                length, i = _varint(page, at)
                rowid, i = _varint(page, i)
                if not wanted(rowid):
                    continue
                values = decode_record(f.payload(page, i, length))
            except (ValueError, IndexError, UnicodeDecodeError, struct.error):
                continue
            yield LeafRecord(n, rowid, values)
