"""Reading and writing the user's files (trace CSV, rig TOML) with clear errors."""

from __future__ import annotations

import os
import tomllib
from pathlib import Path
from typing import Any, Callable, TypeVar

import tomli_w

from measurement.errors import RigError
from measurement.rig import Rig
from measurement.trace import Trace, parse_trace_csv

from .errors import InputFileError

T = TypeVar("T")


def read_text(path: str | os.PathLike, what: str) -> str:
    p = Path(path)
    if not p.exists():
        raise InputFileError(f"{what} {str(p)!r} not found")
    if p.is_dir():
        raise InputFileError(f"{what} {str(p)!r} is a directory; expected a file")
    try:
        return p.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputFileError(f"{what} {str(p)!r} is not UTF-8 text") from None
    except OSError as exc:
        raise InputFileError(f"{what} {str(p)!r} cannot be read: {exc.strerror}") from None


def read_toml(path: str | os.PathLike, what: str) -> dict[str, Any]:
    text = read_text(path, what)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputFileError(f"{what} {str(path)!r} is not valid TOML: {exc}") from None


def read_trace(path: str | os.PathLike) -> Trace:
    """A trace CSV (columns t in s and angle in rad; '#' comments)."""
    text = read_text(path, "trace")
    return parse_trace_csv(text.splitlines(), source=str(path))


def read_toml_as(path: str | os.PathLike, what: str, parse: Callable[[dict], T], error: type[Exception]) -> T:
    """Parse a TOML file with ``parse``; its ``error`` is re-raised with the file name in front."""
    doc = read_toml(path, what)
    try:
        return parse(doc)
    except error as exc:
        raise error(f"{path}: {exc}") from None


def read_rig(path: str | os.PathLike) -> Rig:
    """The rig file (TOML: [rig] kind and constants, [model] declared effects; see README.md)."""
    return read_toml_as(path, "rig file", Rig.from_dict, RigError)


def write_rig(rig: Rig, path: str | os.PathLike, comment: str | None = None) -> None:
    text = tomli_w.dumps(rig.to_dict())
    if comment:
        text = "".join(f"# {line}\n" for line in comment.splitlines()) + text
    Path(path).write_text(text, encoding="utf-8")


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write via a temporary file and rename, so a reader never sees half a file."""
    p = Path(path)
    tmp = p.with_name(f".{p.name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, p)
