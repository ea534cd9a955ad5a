"""Reading the camera file (TOML: [camera], [marker], optional [pose]; see docs/vision.md) with errors that
name the file and the key."""

from __future__ import annotations

import os

from measurement.errors import VisionError
from measurement.vision.config import CameraConfig
from service.sources.files import read_toml_as


def read_camera(path: str | os.PathLike) -> CameraConfig:
    """The camera file at ``path``: intrinsics, distortion, marker radius and distance (and optional [pose])."""
    return read_toml_as(path, "camera file", CameraConfig.from_dict, VisionError)


def camera_config(camera: str | os.PathLike | CameraConfig) -> CameraConfig:
    """A camera file path or an already parsed ``CameraConfig``."""
    return camera if isinstance(camera, CameraConfig) else read_camera(camera)


#: the append-only log of camera-file edits made on the web page, in the state directory
CAMERA_AUDIT_FILE = "camera-audit.log"


def roi_from_typed(typed: dict[str, str], width: int, height: int) -> tuple[int, int, int, int] | None:
    """The region of interest (x0, y0, x1, y1) px of x, y, w, h as typed (whole pixels; all four empty: none,
    the whole frame). VisionError saying which field is wrong and why."""
    texts = [str(typed.get(k) or "").strip() for k in ("x", "y", "w", "h")]
    if not any(texts):
        return None
    values = []
    for key, text in zip("xywh", texts):
        try:
            values.append(int(text))
        except ValueError:
            raise VisionError(f"region of interest {key}: expected a whole number of pixels, got {text!r}") from None
    x, y, w, h = values
    if x < 0 or y < 0:
        raise VisionError(f"region of interest: x and y must be 0 or more, got x = {x}, y = {y}")
    if w < 8 or h < 8:
        raise VisionError(f"region of interest: w and h must be at least 8 px, got w = {w}, h = {h}")
    if x + w > width or y + h > height:
        raise VisionError(f"region of interest: x + w = {x + w} and y + h = {y + h} must lie in the "
                          f"{width}×{height} image")
    return x, y, x + w, y + h


def set_roi(path: str | os.PathLike, roi: tuple[int, int, int, int] | None) -> tuple[CameraConfig, list[int] | None]:
    """Set ``[target] roi`` (x0, y0, x1, y1 px; None removes it) in the camera file at ``path``, keeping its
    comments and layout; the new text must read as a camera file before it replaces the old one in one step
    (VisionError naming the key, the file unchanged). Returns the re-read file and the region it had before."""
    import tomllib

    import tomlkit

    from service.sources.files import read_text, write_atomic

    doc = tomlkit.parse(read_text(path, "camera file"))
    if "target" not in doc:
        doc["target"] = tomlkit.table()
    table = doc["target"]
    before = table.get("roi")
    before = [int(v) for v in before] if before is not None else None
    if roi is None:
        table.pop("roi", None)
    else:
        table["roi"] = list(roi)
    text = tomlkit.dumps(doc)
    try:
        config = CameraConfig.from_dict(tomllib.loads(text))
    except VisionError as exc:
        raise VisionError(f"{path}: {exc}") from None
    write_atomic(path, text, "camera file")
    return config, before


def audit_camera(log_path: str | os.PathLike, who: str, path: str | os.PathLike, before: list[int] | None,
                 after: tuple[int, int, int, int] | None, when: str) -> str:
    """Append one line to the camera audit log (``when`` ISO time, who, the camera file, roi: before → after)
    and return it; the log is only ever appended to."""
    def words(r) -> str:
        return "whole frame" if r is None else "[" + ", ".join(str(int(v)) for v in r) + "]"

    line = f"{when}\t{who}\t{os.fspath(path)}\troi: {words(before)} → {words(after)}\n"
    with open(log_path, "a", encoding="utf-8") as f:
        f.write(line)
    return line
