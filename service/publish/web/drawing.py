"""The tensor set's small axonometric drawing: the part's frame and the swing axis as the page draws them (SVG
coordinates)."""

from __future__ import annotations

import math
from typing import Any

#: the view the tensor set's drawing is seen from: azimuth and elevation, degrees. An isometric view (45°, 35.3°)
#: would draw the axis [1, 1, 0] on top of z (both point at the viewer's vertical); from here no two of the
#: usual six orientations (x, y, z, xy, xz, yz) are drawn within 25° of each other
VIEW_AZIMUTH, VIEW_ELEVATION = 13.0, 28.0


def project(v: Any) -> tuple[float, float]:
    """A direction in the part's frame as seen on the drawing (right, up), from ``VIEW_AZIMUTH``/``VIEW_ELEVATION``."""
    a, e = math.radians(VIEW_AZIMUTH), math.radians(VIEW_ELEVATION)
    x, y, z = (float(t) for t in v)
    right = -math.sin(a) * x + math.cos(a) * y
    up = -math.sin(e) * math.cos(a) * x - math.sin(e) * math.sin(a) * y + math.cos(e) * z
    return right, up


def axes_drawing(axis: Any, offset: Any = None, size: int = 220) -> dict[str, Any]:
    """A small axonometric drawing of the part's frame and the swing axis (SVG coordinates, px): the part's
    x, y, z as arrows from its centre of mass, the swing axis as a line along ``axis`` through the point the
    offset gives (m from the centre of mass)."""
    half = size / 2
    scale = size * 0.32

    def at(v: Any) -> tuple[float, float]:
        r, u = project(v)
        return round(half + scale * r, 1), round(half - scale * u, 1)

    n = [float(t) for t in axis]
    length = math.sqrt(sum(t * t for t in n)) or 1.0
    n = [t / length for t in n]
    d = [float(t) for t in (offset or (0.0, 0.0, 0.0))]
    norm = math.sqrt(sum(t * t for t in d)) or 1.0
    # the swing axis passes the centre of mass at the offset (drawn at most half the frame's length away)
    p = [-t / norm * min(0.5, norm / 0.05) for t in d] if offset else [0.0, 0.0, 0.0]
    a, b = at([p[i] - 1.2 * n[i] for i in range(3)]), at([p[i] + 1.2 * n[i] for i in range(3)])
    return {"size": size, "origin": at((0, 0, 0)),
            "frame": [("x", at((1, 0, 0))), ("y", at((0, 1, 0))), ("z", at((0, 0, 1)))],
            "axis": (a, b), "axis_label": b}
