"""The pictures of docs/vision.md that answer a new user's questions, drawn by the code that does the work.

    .venv/bin/python tools/vision_doc_pictures.py [OUT_DIR]     (default docs/img)

* ``vision-blobs-choice.png``: which two spots ``kind = "blobs"`` takes when more of the colour are in view
  (the real ``BlobLocator`` run on two synthetic frames).
* ``vision-colour-tolerance.png``: which colours a ``colour`` with the default tolerance matches, for a
  saturated red and for a dark green (the locator's own mask over a chart of colours).
* ``vision-pivot-error.png``: what a guessed pivot off by a share of the bob's radius does to the angle
  across a swing (the geometry of ``body.provisional_angle``: the angle of the vector pivot → bob).
"""

from __future__ import annotations

import io
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from measurement.vision.locators import BlobLocator  # noqa: E402
from measurement.vision.target import DEFAULT_TOLERANCE, TargetSpec  # noqa: E402

RED = (200, 30, 40)
DARK_GREEN = (30, 60, 40)
FONT = cv2.FONT_HERSHEY_SIMPLEX


def _label(img: np.ndarray, text: str, at: tuple[int, int], scale: float = 0.5, colour=(0, 0, 0)) -> None:
    cv2.putText(img, text, at, FONT, scale, colour, 1, cv2.LINE_AA)


def _scene(spots: list[tuple[float, float, float]]) -> np.ndarray:
    """A light wall with red discs (u, v, radius px), drawn at 4× and shrunk: sub-pixel edges."""
    w, h, k = 400, 300, 4
    big = np.full((h * k, w * k, 3), (205, 200, 195), np.uint8)
    for u, v, r in spots:
        cv2.circle(big, (int(u * k), int(v * k)), int(r * k), RED[::-1], -1, cv2.LINE_AA)
    return cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA)


def blobs_choice() -> np.ndarray:
    """Two panels: the first frame (the two largest spots in the region) and a later one (each followed in its
    window; a larger spot that appears elsewhere is not taken)."""
    spec = TargetSpec(kind="blobs", colour=RED)
    loc = BlobLocator(spec, 400, 300, count=2)
    first = _scene([(150, 120, 14), (250, 130, 12), (60, 250, 8), (330, 40, 6)])
    o1 = loc.locate(first)
    later = _scene([(156, 124, 14), (254, 138, 12), (60, 250, 8), (330, 40, 6), (200, 240, 22)])
    size = loc._blob_size  # the followed blobs' size sets their windows
    o2 = loc.locate(later)
    panels = []
    for img, obs, title in ((first, o1, "first frame: the two largest spots"),
                            (later, o2, "later: each followed in its window")):
        out = img.copy()
        assert obs.found and obs.a is not None and obs.b is not None
        ends: list[tuple[str, tuple[float, float]]] = [("a", obs.a), ("b", obs.b)]
        for name, p in ends:
            cv2.drawMarker(out, (int(round(p[0])), int(round(p[1]))), (0, 160, 0), cv2.MARKER_CROSS, 16, 2)
            _label(out, name, (int(p[0]) + 10, int(p[1]) - 10), 0.6, (0, 120, 0))
        if img is later:
            half = 1.5 * size + 4
            for was in (o1.a, o1.b):
                assert was is not None
                cv2.rectangle(out, (int(was[0] - half), int(was[1] - half)), (int(was[0] + half), int(was[1] + half)),
                              (0, 200, 255), 1)
            _label(out, "larger, but outside the windows: not taken", (95, 285), 0.45)
        else:
            _label(out, "smaller spots: not taken", (20, 285), 0.45)
        cv2.rectangle(out, (0, 0), (399, 22), (255, 255, 255), -1)
        _label(out, title, (6, 16))
        panels.append(out)
    return np.hstack([panels[0], np.full((300, 6, 3), 255, np.uint8), panels[1]])


def colour_chart() -> np.ndarray:
    """Swatches over hue (columns) and lightness (rows) plus a grey ramp; 24 px each, BGR."""
    cell, hues, levels = 20, 18, 8
    rows = []
    for li in range(levels):
        value = 30 + 225 * li / (levels - 1)
        row = []
        for sat in (1.0, 0.45):
            hsv = np.array([[[int(180 * hi / hues), int(255 * sat), int(value)] for hi in range(hues)]], np.uint8)
            row.append(cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0])
        rows.append(np.concatenate(row))
    grey = np.array([[g, g, g] for g in np.linspace(0, 255, 2 * hues)], np.uint8)
    chart = np.array(rows + [grey], np.uint8)
    return cv2.resize(chart, (chart.shape[1] * cell, chart.shape[0] * cell), interpolation=cv2.INTER_NEAREST)


def colour_tolerance() -> np.ndarray:
    chart = colour_chart()
    h, w = chart.shape[:2]
    panels = []
    for colour, name in ((RED, "red (200, 30, 40)"), (DARK_GREEN, "dark green (30, 60, 40)")):
        loc = BlobLocator(TargetSpec(kind="blob", colour=colour), w, h)
        matched = loc.mask(chart, (0, 0, w, h)) > 0
        out = chart.copy()
        out[~matched] = (0.35 * out[~matched] + 0.65 * 255).astype(np.uint8)  # unmatched: faded
        contours, _ = cv2.findContours(matched.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(out, contours, -1, (0, 0, 0), 2)
        head = np.full((56, w, 3), 255, np.uint8)
        cv2.rectangle(head, (6, 8), (46, 48), colour[::-1], -1)
        share = 100 * matched[:-20].mean()
        _label(head, f"colour = {name}, tolerance {DEFAULT_TOLERANCE:g}: outlined swatches match", (56, 24))
        _label(head, f"({share:.0f} % of the colour swatches; bottom row: greys)", (56, 44))
        panels.append(np.vstack([head, out]))
    gap = np.full((10, panels[0].shape[1], 3), 255, np.uint8)
    return np.vstack([panels[0], gap, panels[1]])


def pivot_error() -> np.ndarray:
    """Angle error across a swing of ±0.4 rad for a pivot guessed off by 5 % of the bob's radius, along the
    rod (the angle is scaled) and across it (an offset and an uneven swing)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    theta = np.linspace(-0.4, 0.4, 201)
    r = 1.0
    bob = np.stack([r * np.sin(theta), r * np.cos(theta)])  # u right, v down, pivot at 0
    fig, ax = plt.subplots(figsize=(7.2, 3.6), dpi=110)
    for du, dv, label in ((0.0, 0.05, "5 % too high (along the rod)"), (0.0, -0.05, "5 % too low"),
                          (0.05, 0.0, "5 % sideways")):
        seen = np.arctan2(bob[0] - du, bob[1] + dv)
        err = seen - theta
        if du:
            err -= err[100]  # the rest angle's offset is taken out as the swing's zero
        ax.plot(theta, np.degrees(err), label=label)
    ax.axhline(0, color="0.6", lw=0.8)
    ax.set_xlabel("swing angle θ (rad)")
    ax.set_ylabel("angle error (°)")
    ax.set_title("pivot guessed off by 5 % of the pivot–bob distance")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    png = io.BytesIO()
    fig.savefig(png, format="png")
    plt.close(fig)
    img = cv2.imdecode(np.frombuffer(png.getvalue(), np.uint8), cv2.IMREAD_COLOR)
    assert img is not None, "matplotlib wrote a PNG"
    return img


def main(argv: list[str]) -> None:
    out = Path(argv[0]) if argv else ROOT / "docs" / "img"
    out.mkdir(parents=True, exist_ok=True)
    for name, draw in (("vision-blobs-choice.png", blobs_choice), ("vision-colour-tolerance.png", colour_tolerance),
                       ("vision-pivot-error.png", pivot_error)):
        assert cv2.imwrite(str(out / name), draw()), name
        print(out / name)


if __name__ == "__main__":
    main(sys.argv[1:])
