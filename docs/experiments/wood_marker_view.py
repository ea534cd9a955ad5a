"""Experiment behind docs/measured-data.md: the camera's view measured from the two markers, release by release.

For each marker track (t, ax, ay, bx, by in px) it prints the view measured
from the markers' distance (measurement.vision.marker_pair), then ω_n and
the effects the loop finds, from the angle as the image shows it (the
loop may fit the scale: gain, view) and from the angle with the measured view
removed (the rig's sensor declared calibrated). Then, for the two releases in
data/, ω_n over the same range of amplitudes (the 120° release from 10 s on,
the 60° release up to 10 s: both ≈ 1.3 → 0.5 rad), ω_n with one model
declared for both (viscous, dahl, quadratic; no discovery), and where the
markers sat on the pendulum: the circles their view-corrected positions
trace about the pivot (radius of b over radius of a, free of the image's
scale).

Run from the repository root:
`.venv/bin/python docs/experiments/wood_marker_view.py`             (the two releases in data/)
`.venv/bin/python docs/experiments/wood_marker_view.py FILE.csv ...` (more releases: a marker track, or a
combined-data CSV of the source repository, whose g_center and r_center columns are the two markers)
"""

import csv
import sys
from pathlib import Path

import numpy as np

from measurement import Options, identify
from measurement.rig import Rig
from measurement.trace import Trace
from measurement.vision.marker_pair import MarkerTrack, measure_view, pair_trace, parse_marker_csv

ROOT = Path(__file__).resolve().parents[2]
AS_SEEN = Rig(kind="compound", declared=("viscous",))
CALIBRATED = Rig(kind="compound", declared=("viscous",), sensor_calibrated=True)


def read_track(path: Path) -> MarkerTrack:
    with open(path, encoding="utf-8") as fh:
        head = [line for line in fh if not line.startswith("#")][:1]
    if head and "g_center" in head[0]:  # the source repository's combined-data file
        with open(path, encoding="utf-8") as fh:
            rows = [r for r in csv.DictReader(fh) if r["g_center"] and r["r_center"]]
        t = np.array([float(r["time"]) for r in rows])
        a = np.array([[float(v) for v in r["g_center"].split(":")] for r in rows])
        b = np.array([[float(v) for v in r["r_center"].split(":")] for r in rows])
        return MarkerTrack(t - t[0], a, b, source=path.name)
    with open(path, encoding="utf-8") as fh:
        return parse_marker_csv(fh, source=path.name)


def circle(p: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre (px) and radius (px) of the circle through points p (algebraic least squares)."""
    x, y = p.T
    c = np.linalg.lstsq(np.column_stack([x, y, np.ones_like(x)]), x * x + y * y, rcond=None)[0]
    centre = c[:2] / 2
    return centre, float(np.sqrt(c[2] + centre @ centre))


def main() -> None:
    paths = [Path(p) for p in sys.argv[1:]] or [ROOT / "data" / "wood_markers_60deg.csv",
                                                 ROOT / "data" / "wood_markers_120deg.csv"]
    print(f"{'release':34s} {'axis ratio':>11s} {'stretch':>8s} {'shear':>8s} {'pattern':>8s} | "
          f"{'as seen: effects':32s} {'ω_n':>8s} | {'view measured: effects':30s} {'ω_n':>17s} {'res/noise':>9s}")
    calibrated = {}
    for path in paths:
        track = read_track(path)
        view = measure_view(track.a, track.b)
        seen = identify(pair_trace(track, None), AS_SEEN)
        trace = pair_trace(track, view)
        fixed = identify(trace, CALIBRATED)
        calibrated[path.name] = trace
        print(f"{path.name:34s} {view.axis_ratio:11.4f} {view.stretch:+8.4f} {view.shear:+8.4f} "
              f"{100 * view.distance_pattern:7.1f}% | {','.join(seen.added_effects):32s} {seen.omega_n:8.4f} | "
              f"{','.join(fixed.added_effects):30s} {fixed.omega_n:8.4f} ± {fixed.omega_n_std:.4f} "
              f"{fixed.residual_rms / fixed.noise_floor:9.2f}")
    if not sys.argv[1:]:
        print("\nthe same amplitudes (≈ 1.3 → 0.5 rad), view measured:")
        for name, (t0, t1) in (("wood_markers_120deg.csv", (10.0, 99.0)), ("wood_markers_60deg.csv", (0.0, 10.0))):
            trace = calibrated[name]
            keep = (trace.t >= t0) & (trace.t <= t1)
            r = identify(Trace(trace.t[keep], trace.angle[keep], source=name), CALIBRATED)
            swing = r.arrays["fitted"] - r.offset.value
            print(f"  {name:26s} {t0:4.0f}–{min(t1, trace.t[-1]):4.1f} s: amplitude {np.max(np.abs(swing[:60])):.2f} → "
                  f"{np.max(np.abs(swing[-60:])):.2f} rad, effects {','.join(r.added_effects) or '(none)'}, "
                  f"ω_n {r.omega_n:.4f} ± {r.omega_n_std:.4f} rad/s")
        print("\nwhere the markers sat (circles of the view-corrected positions about the pivot):")
        for name in calibrated:
            track = read_track(ROOT / "data" / name)
            s = np.asarray(measure_view(track.a, track.b).matrix).reshape(2, 2)
            (ca, ra), (cb, rb) = circle(track.a @ s.T), circle(track.b @ s.T)
            print(f"  {name:26s} pivot at {np.round(ca, 1)} and {np.round(cb, 1)} px; radii {ra:.1f} and {rb:.1f} px, "
                  f"ratio {rb / ra:.3f}")
        one = Rig(kind="compound", declared=("viscous", "dahl", "quadratic"), sensor_calibrated=True)
        print("\none model for both (viscous, dahl, quadratic declared, no discovery), view measured:")
        for name, trace in calibrated.items():
            r = identify(trace, one, Options(discover=False))
            print(f"  {name:26s} ω_n {r.omega_n:.4f} ± {r.omega_n_std:.4f} rad/s, "
                  f"residual/noise {r.residual_rms / r.noise_floor:.2f}")


if __name__ == "__main__":
    main()
