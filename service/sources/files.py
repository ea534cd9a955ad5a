"""Reading and writing the user's files (trace CSV, rig TOML) with clear errors."""

from __future__ import annotations

import contextlib
import os
import tomllib
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, TypeVar

import tomli_w

from measurement.errors import RigError
from measurement.rig import Rig
from measurement.trace import Trace, csv_content, csv_header, parse_trace_csv
from service.errors import InputFileError
from service.sources.calibrations import names_problem

if TYPE_CHECKING:  # the vision package only when a marker track is read
    from measurement.vision.marker_pair import MarkerTrack

T = TypeVar("T")


#: the largest text file read (trace CSV, rig, config), bytes: an hour at 1 kHz is about 90 MB
MAX_INPUT_BYTES = 128 * 1024 * 1024
#: the most rows a trace may have: identification time grows with them (1,000 s at 1 kHz)
MAX_TRACE_ROWS = 1_000_000


def read_text(path: str | os.PathLike, what: str, max_bytes: int = MAX_INPUT_BYTES) -> str:
    """The file as text (UTF-8; a byte-order mark as spreadsheet programs write it is dropped).
    At most ``max_bytes`` are read, so a device like /dev/zero or a huge file is refused, not swallowed."""
    p = Path(path)
    if not p.exists():
        raise InputFileError(f"{what} {str(p)!r} not found")
    if p.is_dir():
        raise InputFileError(f"{what} {str(p)!r} is a directory; expected a file")
    try:
        with open(p, "rb") as f:
            data = f.read(max_bytes + 1)
    except OSError as exc:
        raise InputFileError(f"{what} {str(p)!r} cannot be read: {exc.strerror}") from None
    if len(data) > max_bytes:
        raise InputFileError(f"{what} {str(p)!r} is larger than {max_bytes // (1024 * 1024)} MB; "
                             f"expected a smaller file (cut or decimate it)")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputFileError(f"{what} {str(p)!r} is not UTF-8 text") from None


def read_toml(path: str | os.PathLike, what: str) -> dict[str, Any]:
    text = read_text(path, what)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputFileError(f"{what} {str(path)!r} is not valid TOML: {exc}") from None
    except RecursionError:
        raise InputFileError(f"{what} {str(path)!r} nests tables or arrays too deeply to be a {what}") from None


def _read_samples(path: str | os.PathLike, what: str) -> list[str]:
    """The lines of a CSV of samples, refused when it holds more rows than a trace may."""
    text = read_text(path, what)
    rows = text.count("\n")
    if rows > MAX_TRACE_ROWS + 1000:  # + the header and comment lines
        raise InputFileError(f"{what} {str(path)!r} has {rows:,} lines; expected at most {MAX_TRACE_ROWS:,} samples "
                             "(decimate it: the identification time grows with the samples)")
    return text.splitlines()


def read_trace(path: str | os.PathLike) -> Trace:
    """A trace CSV (columns t in s and angle in rad; '#' comments)."""
    return parse_trace_csv(_read_samples(path, "trace"), source=str(path))


def read_markers(path: str | os.PathLike) -> "MarkerTrack":
    """A marker track CSV (columns t in s, ax, ay, bx, by in px; '#' comments)."""
    from measurement.vision.marker_pair import parse_marker_csv

    return parse_marker_csv(_read_samples(path, "marker track"), source=str(path))


def read_samples(path: str | os.PathLike) -> "Trace | MarkerTrack":
    """A trace CSV, or a marker track CSV when its header has the markers' columns and no angle."""
    from measurement.vision.marker_pair import MARKER_COLUMNS, parse_marker_csv

    lines = _read_samples(path, "trace")
    cells = set(csv_header(csv_content(lines)))
    if "angle" not in cells and set(MARKER_COLUMNS) <= cells:
        return parse_marker_csv(lines, source=str(path))
    return parse_trace_csv(lines, source=str(path))


def read_toml_as(path: str | os.PathLike, what: str, parse: Callable[[dict], T], error: type[Exception]) -> T:
    """Parse a TOML file with ``parse``; its ``error`` is re-raised with the file name in front."""
    doc = read_toml(path, what)
    try:
        return parse(doc)
    except error as exc:
        raise error(f"{path}: {exc}") from None


def read_rig(path: str | os.PathLike) -> Rig:
    """The rig file (TOML: [rig] kind and constants, [model] declared effects; see README.md); the names of its
    calibration's references and certificates checked as every name is (they reach the terminal and the page)."""
    rig = read_toml_as(path, "rig file", Rig.from_dict, RigError)
    if rig.calibration is not None and (problem := names_problem({"references": list(rig.calibration.references)})):
        raise RigError(f"{path}: [calibration] references: {problem}")
    return rig


def write_rig(rig: Rig, path: str | os.PathLike, comment: str | None = None,
              keep_from: str | os.PathLike | None = None) -> None:
    """Write ``rig`` as a rig file. keep_from: the rig file it came from; its comments, key order
    and layout are kept (tomlkit edits the document in place) and only the values change."""
    if keep_from is not None:
        import tomlkit

        doc = tomlkit.parse(read_text(keep_from, "rig file"))
        values = rig.to_dict()
        if "calibration" in values and hasattr(doc.get("calibration"), "items"):
            # a new calibration: nothing of the old one's table holds (its reproducibility figure, say)
            for key in set(doc["calibration"]) - set(values["calibration"]):
                del doc["calibration"][key]
        _update_toml(doc, values)
        text = tomlkit.dumps(doc)
        if comment and comment not in text:
            text = "".join(f"# {line}\n" for line in comment.splitlines()) + text
    else:
        text = tomli_w.dumps(rig.to_dict())
        if comment:
            text = "".join(f"# {line}\n" for line in comment.splitlines()) + text
    write_atomic(path, text, "rig file")


def _update_toml(doc: Any, values: dict[str, Any]) -> None:
    """Set ``values`` in the tomlkit document ``doc``, table by table, keeping what is not set."""
    for key, value in values.items():
        if isinstance(value, dict) and key in doc and hasattr(doc[key], "items") and value:
            _update_toml(doc[key], value)
        else:
            doc[key] = value


def check_output_path(path: str | os.PathLike, what: str = "output file") -> Path:
    """``path`` as a place to write a new file: a regular file there is replaced, anything else
    (a directory, a device node, a FIFO, a symbolic link) is refused, and the folder must exist."""
    p = Path(path)
    if p.is_symlink():
        raise InputFileError(f"{what} {str(p)!r} is a symbolic link; refusing to replace it (give the real path)")
    if p.exists() and not p.is_file():
        kind = "a directory" if p.is_dir() else "not a regular file (a device, FIFO or socket)"
        raise InputFileError(f"{what} {str(p)!r} is {kind}; expected a file name")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise InputFileError(f"{what} {str(p)!r}: folder {str(parent)!r} does not exist")
    return p


def write_atomic(path: str | os.PathLike, data: str | bytes, what: str = "output file") -> None:
    """Write via a temporary file in the same folder and rename it over ``path``, so a reader never
    sees half a file; on failure nothing is left behind and the error is one InputFileError line."""
    import tempfile

    p = check_output_path(path, what)
    payload = data.encode("utf-8") if isinstance(data, str) else data
    tmp: str | None = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent if str(p.parent) else ".")
        with os.fdopen(fd, "wb") as f:
            f.write(payload)
        if p.exists():
            os.chmod(tmp, p.stat().st_mode & 0o7777)  # replacing a file keeps its permissions
        else:
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)  # a new file gets the usual mode, not mkstemp's 0600
        os.replace(tmp, p)
        tmp = None
    except OSError as exc:
        raise InputFileError(f"cannot write {what} {str(p)!r}: {exc.strerror or exc}") from None
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write via a temporary file and rename, so a reader never sees half a file."""
    write_atomic(path, text)
