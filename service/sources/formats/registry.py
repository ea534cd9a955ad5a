"""The export formats moi reads: adding one is one module and one line here.

Each entry names the format and the module of its ``FORMAT`` (a ``Format``); a file is read by the
first format, in this order, whose ``sniff`` recognises its content (the file's name alone decides
nothing: a Tracker export is a ``.txt``, a phyphox export a folder, a zip or a ``.csv``).
"""

from __future__ import annotations

import importlib
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from service.errors import InputFileError

from .log import Log

#: the characters of a file's beginning a format is recognised by
HEAD_CHARS = 65536


@dataclass(frozen=True)
class Probe:
    """What sniffing sees of a source: its path, the text of its beginning ('' for a folder, a zip or a
    binary file) and the names of the files inside a folder or a zip (relative, '/'-separated)."""

    path: Path
    head: str
    members: tuple[str, ...]

    @classmethod
    def of(cls, path: Path) -> Probe:
        if path.is_dir():
            return cls(path, "", tuple(sorted(p.relative_to(path).as_posix() for p in path.rglob("*") if p.is_file())))
        if zipfile.is_zipfile(path):
            with zipfile.ZipFile(path) as z:
                return cls(path, "", tuple(sorted(n for n in z.namelist() if not n.endswith("/"))))
        with open(path, "rb") as f:
            raw = f.read(HEAD_CHARS)
        try:
            head = raw.decode("utf-8-sig")
        except UnicodeDecodeError:
            head = raw.decode("latin-1") if b"\x00" not in raw else ""
        return cls(path, head, ())


@dataclass(frozen=True)
class Format:
    """One export format: its name, a line on what it is, an example command, how it is recognised and read."""

    name: str
    what: str
    example: str
    sniff: Callable[[Probe], bool]
    read: Callable[[Probe], Log]


@dataclass(frozen=True)
class FormatEntry:
    name: str
    module: str

    def load(self) -> Format:
        fmt: Format = importlib.import_module(self.module).FORMAT
        return fmt


FORMATS: tuple[FormatEntry, ...] = (
    FormatEntry("phyphox", "service.sources.formats.phyphox"),
    FormatEntry("phyphox-xml", "service.sources.formats.phyphox_xml"),
    FormatEntry("tracker-trk", "service.sources.formats.trk"),
    FormatEntry("tracker", "service.sources.formats.tracker"),
    FormatEntry("logger-pro", "service.sources.formats.vernier"),
    FormatEntry("capstone", "service.sources.formats.pasco"),
    FormatEntry("table", "service.sources.formats.generic"),
)


def formats() -> tuple[Format, ...]:
    return tuple(e.load() for e in FORMATS)


def read_log(path: str | Path) -> Log:
    """The export at ``path`` read by the first format that recognises it (InputFileError: none does)."""
    p = Path(path)
    if not p.exists():
        raise InputFileError(f"{str(p)!r} not found")
    if not (p.is_dir() or p.is_file()):
        raise InputFileError(f"{str(p)!r} is not a regular file (a device, FIFO or socket); expected a file or a folder")
    try:
        probe = Probe.of(p)
    except (OSError, zipfile.BadZipFile) as exc:
        raise InputFileError(f"{str(p)!r} cannot be read: {exc}") from None
    for fmt in formats():
        if fmt.sniff(probe):
            return fmt.read(probe)
    binary = " (a binary file or an archive, as a spreadsheet's .xls or .xlsx is: save it as CSV)" if not probe.head else ""
    raise InputFileError(f"{str(p)!r} is not a format moi reads{binary}; expected one of "
                         f"{', '.join(f.name for f in formats())} (see moi identify --help)")


def describe() -> list[tuple[str, str, str]]:
    """(name, what, example) of every format, for the help and the docs."""
    return [(f.name, f.what, f.example) for f in formats()]


def member_text(probe: Probe, name: str, what: str) -> str:
    """The text of ``name`` inside the folder or zip of ``probe``."""
    from service.sources.files import MAX_INPUT_BYTES, read_text

    if probe.path.is_dir():
        return read_text(probe.path / name, what)
    with zipfile.ZipFile(probe.path) as z:
        info = z.getinfo(name)
        if info.file_size > MAX_INPUT_BYTES:
            raise InputFileError(f"{what} {name!r} in {str(probe.path)!r} is larger than "
                                 f"{MAX_INPUT_BYTES // (1024 * 1024)} MB")
        try:
            return z.read(name).decode("utf-8-sig")
        except UnicodeDecodeError:
            raise InputFileError(f"{what} {name!r} in {str(probe.path)!r} is not UTF-8 text") from None


def whole_text(probe: Probe, what: str) -> str:
    from service.sources.files import read_text

    return read_text(probe.path, what)


