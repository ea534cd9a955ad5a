"""Experiment behind docs/measured-data.md: is the 60° session's rising frequency in the pendulum or in the video's clock?

The 60° video's timestamps are frame index / 59.9 (a frame rate typed in by
hand), so frames lost or a wrong rate would shorten the periods just as a
stiffer pendulum would. The same release was also recorded by an
accelerometer strapped to the pendulum and read by a computer with its own
clock (public repository georgePadolsey/PendulaTools, commit ad136f3, file
accel_data/WoodenPendula60degSecondTry.txt: columns time (s), then three
8-bit axes; its time 0 is the start of data/wood_pendulum_60deg.csv, as that
repository's OpenCV-Processor/vid_data.py states with time_start 20.25 s).

The radial axis sees g·cos θ + r·θ'², which repeats twice per swing: every
second upward crossing of its mean is one full period. This script prints,
in 2 s windows, the mean full period from the camera's zero crossings and
from the accelerometer's, and their ratio; then the mean period over longer
spans (a 60 frames/s clock instead of 59.9 would make the ratio 0.9983).

Run from the repository root, with the accelerometer file fetched from that
repository: `.venv/bin/python docs/experiments/wood_accelerometer_clock.py PATH/TO/WoodenPendula60degSecondTry.txt`

With a trace as a second argument it compares the two clocks for any
release, without knowing where the accelerometer record starts: the radial
axis is fitted, window by window, as c₀ + c₁·cos θ + c₂·θ'² + c₃·sin θ + c₄·θ''
of the camera's swing shifted by a delay; the delay's drift over the record
is the clock ratio (0: the video's frame rate is right; a video at 60 frames/s
stamped as 59.9 would drift by +0.17 %). For the 120° release:
`... wood_accelerometer_clock.py PATH/TO/WoodenPendula120.txt data/wood_pendulum_120deg.csv`
"""

import sys
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import least_squares
from scipy.signal import butter, filtfilt

ROOT = Path(__file__).resolve().parents[2]


def read_accelerometer(path: str) -> np.ndarray:
    rows, inside = [], False
    with open(path, encoding="utf-8", errors="replace") as fh:
        lines = list(fh)
    for line in lines:
        low = line.lower()
        if "=== begin data ===" in low:
            inside = True
        elif "=== end data ===" in low:
            break
        elif inside:
            parts = line.split("\t")
            if len(parts) == 4:
                rows.append([float(p) for p in parts])
    return np.asarray(rows)


def upward_crossings(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    i = np.where((y[:-1] < 0) & (y[1:] >= 0))[0]
    return t[i] - y[i] * (t[i + 1] - t[i]) / (y[i + 1] - y[i])


def clock_drift(acc: np.ndarray, trace_path: str) -> None:
    """Print the delay between the camera's swing and the accelerometer, window by window, and its drift."""
    from measurement import parse_trace_csv

    with open(trace_path, encoding="utf-8") as fh:
        cam = parse_trace_csv(fh, source=trace_path)
    fs = 100.0
    t = np.arange(acc[0, 0] + 0.05, acc[-1, 0] - 0.05, 1 / fs)
    b, a = butter(4, 6.0 / (fs / 2))
    radial = filtfilt(b, a, np.interp(t, acc[:, 0], acc[:, 2]))
    bc, ac = butter(4, 6.0 / (cam.sample_rate / 2))
    swing = CubicSpline(cam.t, filtfilt(bc, ac, cam.angle - np.median(cam.angle[-120:])))
    rate, accel = swing.derivative(), swing.derivative(2)

    def misfit(delay: float, where: np.ndarray) -> np.ndarray:
        tt = t[where] + delay
        inside = (tt > cam.t[0] + 0.5) & (tt < cam.t[-1] - 0.5)
        x = swing(tt[inside])
        X = np.column_stack([np.ones_like(x), np.cos(x), rate(tt[inside]) ** 2, np.sin(x), accel(tt[inside])])
        y = radial[where][inside]
        out = np.full(where.sum(), 30.0)  # a delay that leaves the record costs as a poor fit
        out[inside] = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
        return out

    everywhere = np.ones(t.size, dtype=bool)
    start = min((np.sum(misfit(d, everywhere) ** 2), d) for d in np.arange(-25.0, cam.t[-1] - 5.0, 0.05))[1]
    start = float(least_squares(lambda p: misfit(p[0], everywhere), [start], x_scale=[0.01]).x[0])
    print("window centre [s]  delay camera − accelerometer [s]")
    centres, delays = [], []
    for lo in np.arange(t[0] + 1.0, t[-1] - 3.0, 2.0):
        where = (t >= lo) & (t < lo + 3.0)
        d = float(least_squares(lambda p: misfit(p[0], where), [start], x_scale=[0.01]).x[0])
        centres.append(lo + 1.5)
        delays.append(d)
        print(f"{lo + 1.5:10.1f}         {d:+.4f}")
    slope = np.polyfit(centres, delays, 1)[0]
    print(f"drift of the delay: {slope:+.5f} s/s: the video's clock runs {100 * slope:+.3f} % against the "
          f"accelerometer's (a 60 frames/s video stamped at 59.9 would give +0.167 %)")


def main() -> None:
    acc = read_accelerometer(sys.argv[1])
    if len(sys.argv) > 2:
        clock_drift(acc, sys.argv[2])
        return
    fs = 500.0
    t = np.arange(acc[0, 0], acc[-1, 0], 1 / fs)
    radial = np.interp(t, acc[:, 0], acc[:, 2])  # the axis that swings (counts; 24 counts = 1 g)
    b, a = butter(4, 5.0 / (fs / 2))
    radial = filtfilt(b, a, radial)
    n = int(2 * 1.08 * fs)  # two periods: the moving mean the signal swings about
    centred = radial - np.convolve(radial, np.ones(n) / n, mode="same")
    c_acc = upward_crossings(t[n:-n], centred[n:-n])
    p_acc = c_acc[2:] - c_acc[:-2]

    cam = np.loadtxt(ROOT / "data" / "wood_pendulum_60deg.csv", delimiter=",", comments="#", skiprows=2)
    rest = np.median(cam[-300:, 1])
    c_cam = upward_crossings(cam[:, 0], cam[:, 1] - rest)
    p_cam = np.diff(c_cam)

    print("window [s]  camera period [s]  accelerometer period [s]  ratio")
    for lo in range(2, 20, 2):
        mc = (c_cam[:-1] >= lo) & (c_cam[:-1] < lo + 2)
        ma = (c_acc[:-2] >= lo) & (c_acc[:-2] < lo + 2)
        if mc.any() and ma.any():
            pc, pa = p_cam[mc].mean(), p_acc[ma].mean()
            print(f"{lo:4d}–{lo + 2:<4d}   {pc:10.4f}         {pa:10.4f}              {pc / pa:.4f}")
    # the mean period over longer spans: slope of the crossing times against their count
    # (the accelerometer crosses twice per period)
    for lo, hi in ((2, 18), (2, 10), (10, 18)):
        mc = c_cam[(c_cam >= lo) & (c_cam <= hi)]
        ma = c_acc[(c_acc >= lo - 0.3) & (c_acc <= hi + 0.3)]
        pc = np.polyfit(np.arange(mc.size), mc, 1)[0]
        pa = 2 * np.polyfit(np.arange(ma.size), ma, 1)[0]
        print(f"{lo}–{hi} s: camera {pc:.5f} s, accelerometer {pa:.5f} s, ratio {pc / pa:.5f}")


if __name__ == "__main__":
    main()
