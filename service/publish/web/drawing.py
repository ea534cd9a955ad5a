"""The tensor set's small axonometric drawing: the part's frame and the swing axis as the page draws them (SVG
coordinates)."""

from __future__ import annotations

import math
from typing import Any

#: the view the tensor set's drawing is seen from: azimuth and elevation, degrees. An isometric view (45°, 35.3°)
#: would draw the axis [1, 1, 0] on top of z (both point at the viewer's vertical); from here no two of the usual six
#: orientations (x, y, z, xy, xz, yz) are drawn within 20° of each other, and no axis of the part's frame at less than
#: two thirds of its length (x seen nearly end-on was a stub)
VIEW_AZIMUTH, VIEW_ELEVATION = 38.0, 19.0
#: px: the drawing's margin, and the swing axis label's font size and width (10 characters of 12 px)
PAD, LABEL_SIZE, LABEL_WIDTH = 16.0, 12, 66.0


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
    offset gives (m from the centre of mass), scaled to fill the square of ``size`` px; its label beside its upper
    end, inside the square."""
    n = [float(t) for t in axis]
    length = math.sqrt(sum(t * t for t in n)) or 1.0
    n = [t / length for t in n]
    d = [float(t) for t in (offset or (0.0, 0.0, 0.0))]
    norm = math.sqrt(sum(t * t for t in d)) or 1.0
    # the swing axis passes the centre of mass at the offset (drawn at most half the frame's length away)
    p = [-t / norm * min(0.5, norm / 0.05) for t in d] if offset else [0.0, 0.0, 0.0]
    ends = [project([p[i] - 1.2 * n[i] for i in range(3)]), project([p[i] + 1.2 * n[i] for i in range(3)])]
    frame = [project(v) for v in ((1, 0, 0), (0, 1, 0), (0, 0, 1))]
    pts = [(0.0, 0.0), *frame, *ends]
    lo_r, hi_r = min(r for r, _ in pts), max(r for r, _ in pts)
    lo_u, hi_u = min(u for _, u in pts), max(u for _, u in pts)
    scale = (size - 2 * PAD) / max(hi_r - lo_r, hi_u - lo_u, 1e-9)
    mid_r, mid_u = (lo_r + hi_r) / 2, (lo_u + hi_u) / 2

    def at(ru: tuple[float, float]) -> tuple[float, float]:
        return round(size / 2 + scale * (ru[0] - mid_r), 1), round(size / 2 - scale * (ru[1] - mid_u), 1)

    a, b = at(ends[0]), at(ends[1])
    top = a if a[1] < b[1] else b  # the label by the upper end, on the side with room, never past the edge
    anchor = "end" if top[0] > size / 2 else "start"
    x = top[0] - 6 if anchor == "end" else top[0] + 6
    x = max(LABEL_WIDTH + 2, x) if anchor == "end" else min(size - LABEL_WIDTH - 2, x)
    # above the end, clear of the line; below it when the end is at the top edge
    y = top[1] - 8 if top[1] - 8 >= LABEL_SIZE + 2.0 else min(top[1] + LABEL_SIZE + 6, size - 4.0)
    return {"size": size, "origin": at((0.0, 0.0)),
            "frame": [(name, at(end)) for name, end in zip("xyz", frame)],
            "axis": (a, b), "axis_label": (round(x, 1), round(y, 1), anchor)}
