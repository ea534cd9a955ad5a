"""What the camera tracks on the swinging body and how it looks at the swing: the ``[target]`` table.

```toml
[target]
kind = "tag"              # tag | blob | blobs | patch | edge
view = "face-on"          # face-on | along-axis | side (side: the edge on a cylinder)
roi = [x0, y0, x1, y1]    # px, the region searched (default: the whole frame)
dictionary = "4X4_50"     # tag: an OpenCV ArUco/AprilTag dictionary (default 4X4_50)
id = 7                    # tag: which tag (default: the first one found)
colour = [200, 30, 40]    # blob(s): the target's colour, R G B 0–255 (default: by brightness)
tolerance = 20.0          # blob(s): how far the colour may stray, CIELAB units (a*, b*; L* three times that; default 20)
polarity = "dark"         # blob(s) without a colour: darker or brighter than its surroundings
pivot = [u, v]            # blob: the pivot (or the torsion axis), px (default: the centre of the arc)
```

Kinds (each gives, per frame, a vector fixed to the body whose direction in the
image is the swing angle; ``edge`` keeps its own cylinder geometry):

* ``tag``: a printed ArUco or AprilTag (OpenCV's detector): the vector from its top
  from all four sides. The recommended target.
* ``blob``: one bob of a colour (or dark/bright): the vector from the pivot to its centre.
* ``blobs``: two blobs on the body: the vector from one to the other.
* ``patch``: the texture of the body inside ``roi`` in the first frame; its in-plane
  rotation is followed by enhanced correlation alignment (``cv2.findTransformECC``).
* ``edge``: the vertical dark/bright edge on a cylinder seen from the side (``[marker]``).

Views: ``face-on`` (the swing plane faces the camera), ``along-axis`` (a torsion or
trifilar platform from above or below; the same in-plane geometry), ``side`` (the
cylinder's edge). Errors are ``VisionError`` naming the key (exit status 2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

from ..errors import VisionError

KINDS = ("tag", "blob", "blobs", "patch", "edge")
VIEWS = ("face-on", "along-axis", "side")
POLARITIES = ("dark", "bright")
TARGET_KEYS = ("kind", "view", "roi", "dictionary", "id", "colour", "tolerance", "polarity", "pivot")
#: the tag family printed by default (docs/img/tag-4x4_50-0.png)
DEFAULT_DICTIONARY = "4X4_50"
DEFAULT_TOLERANCE = 20.0


def _numbers(key: str, value: Any, n: int, unit: str) -> tuple[float, ...]:
    if (not isinstance(value, list) or len(value) != n
            or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) for v in value)):
        raise VisionError(f"camera file: [target] {key} must be a list of {n} numbers ({unit}), got {value!r}")
    return tuple(float(v) for v in value)


@dataclass(frozen=True)
class TargetSpec:
    """The target and the view, as the camera file gives them (see the module's docstring).

    roi: (x0, y0, x1, y1) px, x1/y1 exclusive, or None (the whole frame). colour: R, G, B or None.
    pivot: (u, v) px or None. tag_id: None for the first tag found.
    """

    kind: str = "edge"
    view: str = "side"
    roi: tuple[int, int, int, int] | None = None
    dictionary: str = DEFAULT_DICTIONARY
    tag_id: int | None = None
    colour: tuple[float, float, float] | None = None
    tolerance: float = DEFAULT_TOLERANCE
    polarity: str = "dark"
    pivot: tuple[float, float] | None = None

    @property
    def needs_colour(self) -> bool:
        """Frames must be decoded in colour (a colour blob)."""
        return self.colour is not None and self.kind in ("blob", "blobs")

    @classmethod
    def from_dict(cls, t: Mapping[str, Any], width: int, height: int) -> "TargetSpec":
        unknown = sorted(set(t) - set(TARGET_KEYS))
        if unknown:
            raise VisionError(f"camera file: unknown key(s) in [target]: {unknown}; expected {', '.join(TARGET_KEYS)}")
        kind = t.get("kind", "edge")
        if kind not in KINDS:
            raise VisionError(f"camera file: [target] kind must be one of {', '.join(KINDS)}, got {kind!r}")
        view = t.get("view", "side" if kind == "edge" else "face-on")
        if view not in VIEWS:
            raise VisionError(f"camera file: [target] view must be one of {', '.join(VIEWS)}, got {view!r}")
        if (view == "side") != (kind == "edge"):
            raise VisionError(f"camera file: [target] view {view!r} does not go with kind {kind!r}; the side view "
                              "is the edge on a cylinder, the other kinds are seen face-on or along the axis")
        roi = None
        if "roi" in t:
            x0, y0, x1, y1 = (int(round(v)) for v in _numbers("roi", t["roi"], 4, "x0, y0, x1, y1 in px"))
            if not (0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height) or x1 - x0 < 8 or y1 - y0 < 8:
                raise VisionError(f"camera file: [target] roi {t['roi']!r} must lie in the {width}×{height} image "
                                  "with x0 < x1 and y0 < y1, at least 8 px each way")
            roi = (x0, y0, x1, y1)
        dictionary = t.get("dictionary", DEFAULT_DICTIONARY)
        if not isinstance(dictionary, str) or not dictionary_name(dictionary):
            raise VisionError(f"camera file: [target] dictionary must name an OpenCV ArUco/AprilTag dictionary "
                              f"(e.g. 4X4_50, 6X6_250, APRILTAG_36h11), got {dictionary!r}")
        tag_id = t.get("id")
        if tag_id is not None and (isinstance(tag_id, bool) or not isinstance(tag_id, int) or tag_id < 0):
            raise VisionError(f"camera file: [target] id must be a whole number ≥ 0, got {tag_id!r}")
        colour = None
        if "colour" in t:
            r, g, b = _numbers("colour", t["colour"], 3, "R, G, B from 0 to 255")
            colour = (r, g, b)
            if not all(0 <= c <= 255 for c in colour):
                raise VisionError(f"camera file: [target] colour must be R, G, B from 0 to 255, got {t['colour']!r}")
        tolerance = t.get("tolerance", DEFAULT_TOLERANCE)
        if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or not 0 < tolerance < 200:
            raise VisionError(f"camera file: [target] tolerance must be a colour distance between 0 and 200, got {tolerance!r}")
        polarity = t.get("polarity", "dark")
        if polarity not in POLARITIES:
            raise VisionError(f"camera file: [target] polarity must be dark or bright, got {polarity!r}")
        pivot = None
        if "pivot" in t:
            pu, pv = _numbers("pivot", t["pivot"], 2, "u, v in px")
            pivot = (pu, pv)
        return cls(kind=kind, view=view, roi=roi, dictionary=dictionary, tag_id=tag_id, colour=colour,
                   tolerance=float(tolerance), polarity=polarity, pivot=pivot)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": self.kind, "view": self.view}
        if self.roi is not None:
            out["roi"] = list(self.roi)
        if self.kind == "tag":
            out["dictionary"] = self.dictionary
            if self.tag_id is not None:
                out["id"] = self.tag_id
        if self.kind in ("blob", "blobs"):
            if self.colour is not None:
                out["colour"] = list(self.colour)
                out["tolerance"] = self.tolerance
            else:
                out["polarity"] = self.polarity
        if self.pivot is not None:
            out["pivot"] = list(self.pivot)
        return out


#: OpenCV's predefined dictionaries (cv2.aruco.DICT_*), named here so that reading a camera file needs no OpenCV
_DICTIONARIES = ({f"{n}X{n}_{k}" for n in (4, 5, 6, 7) for k in (50, 100, 250, 1000)}
                 | {"ARUCO_ORIGINAL", "ARUCO_MIP_36h12", "APRILTAG_16h5", "APRILTAG_25h9", "APRILTAG_36h10",
                    "APRILTAG_36h11"})


def dictionary_name(name: str) -> str:
    """OpenCV's constant for a dictionary name ('4X4_50', 'DICT_4X4_50', 'apriltag_36h11'), '' if there is none."""
    key = name.upper().removeprefix("DICT_")
    for candidate in _DICTIONARIES:
        if candidate.upper() == key:
            return f"DICT_{candidate}"
    return ""
