"""Long records: `moi identify` of a 30-minute H.264 video and of a 100,000-row trace, peak memory and time.

A record's cost must follow its swing, not its length squared: a camera left running for half an hour, or
an encoder logged for as long, is identified in bounded memory (goal: peak ≤ 500 MB).

The video: a lightly damped torsion pendulum (viscous, c = 2e-5 N·m·s/rad: it still swings ±0.05 rad after
30 minutes, so the camera-yaw fit spans all of it, thousands of knots) seen by the edge camera at 320×240
and 60 frames/s, rendered with the repository's marker renderer (blur σ 1 px, noise σ 2 grey levels) and
encoded by FFmpeg (libx264, CRF 18). Two traces of 100,000 rows (CSV, t and angle): the angle the same
video's tracker reads (at yaw 0, the camera's true one), which is what a user exports; and a real-like
record that is mostly rest: a swing stopped dead by dry friction after about 70 s, then 26 minutes of the
pendulum at rest, sampled at 60 Hz with white noise (σ 2e-4 rad) and timestamp jitter (5 % of the
interval).

Each `moi identify` runs in a child process; its peak resident memory is the child's ``ru_maxrss``
(``resource.getrusage(RUSAGE_CHILDREN)`` of a fresh process that waits for it alone), its time the wall
clock, median of ``--repeats`` runs (default 1: the video's alone takes minutes) pinned to core 0.

    .venv/bin/python bench/bench_long_records.py [--minutes 30] [--rows 100000] [--repeats 1] [--keep DIR]
        [--only video|trace]
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

W, H, FPS = 320, 240, 60.0
RIG_TOML = '[rig]\nkind = "torsion"\nstiffness = 0.3651\n[model]\ndeclared = ["viscous"]\n'
J_TRUE = 0.0125
VIDEO_EFFECTS = {"viscous": {"c": 2e-5}}  # swings to the end of the record
TRACE_EFFECTS = {"viscous": {"c": 1.5e-4}, "coulomb": {"Tc": 3e-4}}  # stops dead after about 70 s
THETA0 = 0.2

#: waits for one command and prints its peak resident memory (KiB on Linux) and wall time as JSON
CHILD = """
import json, resource, subprocess, sys, time
t0 = time.perf_counter()
done = subprocess.run(sys.argv[1:], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
took = time.perf_counter() - t0
peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
print(json.dumps({"rc": done.returncode, "s": took, "maxrss_kib": peak, "out": done.stdout, "err": done.stderr[-2000:]}))
"""


def camera_and_marker():
    from measurement.vision import CameraModel, MarkerGeometry

    return (CameraModel(width=W, height=H, fps=FPS, fx=300.0, fy=300.0, cx=159.5, cy=119.5),
            MarkerGeometry(radius=0.10, distance=0.25))


def camera_toml() -> str:
    import tomli_w

    camera, marker = camera_and_marker()
    return tomli_w.dumps({"camera": camera.to_dict(), "marker": marker.to_dict()})


def render_video(path: pathlib.Path, minutes: float) -> pathlib.Path:
    """The swing of ``minutes``, every frame rendered, as H.264 in MP4."""
    from measurement import Pendulum, Rig, Swing
    from measurement.vision import Imaging, MarkerRenderer

    camera, marker = camera_and_marker()
    renderer = MarkerRenderer(camera, marker, imaging=Imaging(blur=1.0, noise=2.0), seed=7)
    rig = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))
    n = int(minutes * 60 * FPS)
    swing = Swing(Pendulum(rig, J_TRUE, VIDEO_EFFECTS), theta0=THETA0, duration=n / FPS)
    cmd = ["ffmpeg", "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "gray", "-s", f"{W}x{H}",
           "-framerate", f"{FPS:g}", "-i", "-", "-c:v", "libx264", "-preset", "veryfast", "-crf", "18",
           "-pix_fmt", "yuv420p", str(path)]
    with subprocess.Popen(cmd, stdin=subprocess.PIPE) as enc:
        assert enc.stdin is not None
        for k in range(n):
            enc.stdin.write(renderer.render(swing.angle(k / FPS)).tobytes())
        enc.stdin.close()
        if enc.wait() != 0:
            raise RuntimeError("ffmpeg failed to encode the long video")
    return path


def real_like_trace(path: pathlib.Path, rows: int) -> pathlib.Path:
    """A swing that stops dead, then rest, ``rows`` samples at 60 Hz with noise and timestamp jitter."""
    from measurement import Pendulum, Rig, simulate_trace

    rig = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))
    trace = simulate_trace(Pendulum(rig, J_TRUE, TRACE_EFFECTS), theta0=THETA0, duration=(rows - 121) / FPS,
                           rate=FPS, noise_std=2e-4, jitter=0.05, pre_trigger=2.0, seed=4)
    np.savetxt(path, np.column_stack([trace.t, trace.angle]), delimiter=",", header="t,angle", comments="",
               fmt="%.6f")
    return path


def tracked_trace(video: pathlib.Path, camera: pathlib.Path, path: pathlib.Path, rows: int) -> pathlib.Path:
    """The video's tracked angle, its first ``rows`` samples, as a trace CSV (t, angle)."""
    from measurement.vision.pipeline import VisionSettings
    from service.sources.video import video_trace

    trace = video_trace(video, camera, vision=VisionSettings(estimate_yaw=False))
    np.savetxt(path, np.column_stack([trace.t[:rows] - trace.t[0], trace.angle[:rows]]), delimiter=",",
               header="t,angle", comments="", fmt="%.7f")
    return path


def identify(args: list[str], repeats: int) -> dict:
    """``moi identify`` in a child pinned to core 0: median time, the largest peak memory, the JSON answer."""
    moi = [sys.executable, "-c", "import sys; from service.cli import main; sys.exit(main(sys.argv[1:]))"]
    pin = ["taskset", "-c", "0"] if shutil.which("taskset") else []
    runs = []
    for _ in range(repeats):
        done = subprocess.run([*pin, sys.executable, "-c", CHILD, *moi, "identify", *args, "--json"],
                              capture_output=True, text=True, cwd=ROOT, check=True)
        runs.append(json.loads(done.stdout))
    if any(r["rc"] != 0 for r in runs):
        return {"rc": [r["rc"] for r in runs], "err": runs[-1]["err"]}
    out = json.loads(runs[-1]["out"])
    return {"rc": 0, "s": statistics.median(r["s"] for r in runs), "mb": max(r["maxrss_kib"] for r in runs) / 1024,
            "J": out["J"], "window": out["window"]}


def report(name: str, r: dict) -> None:
    if r["rc"] != 0:
        print(f"{name}: FAILED (exit {r['rc']}): {r['err'].strip().splitlines()[-1:]}")
        return
    w = r["window"]
    print(f"{name}: peak {r['mb']:.0f} MB (goal ≤ 500), {r['s']:.1f} s (median), J error "
          f"{100 * (r['J'] / J_TRUE - 1):+.4f} %, fitted {w['n_used']} of {w['n_total']} samples, "
          f"{w['t_start']:.1f}–{w['t_stop']:.1f} s")


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=30.0)
    p.add_argument("--rows", type=int, default=100_000)
    p.add_argument("--repeats", type=int, default=1, help="runs of each (the video's takes minutes)")
    p.add_argument("--keep", type=pathlib.Path, help="folder to keep (and reuse) the video and the trace in")
    p.add_argument("--only", choices=("video", "trace"), help="the video and its track, or the mostly-at-rest trace")
    a = p.parse_args(argv if argv is not None else [])
    if shutil.which("ffmpeg") is None:
        print("no ffmpeg on PATH: the long video cannot be encoded (make ffmpeg)")
        return
    with tempfile.TemporaryDirectory() as tmp:
        folder = a.keep or pathlib.Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "rig.toml").write_text(RIG_TOML)
        (folder / "cam.toml").write_text(camera_toml())
        video = folder / f"long_{a.minutes:g}min.mp4"
        if a.only != "trace" and not video.exists():
            t0 = time.perf_counter()
            render_video(video, a.minutes)
            print(f"rendered and encoded {a.minutes:g} min ({int(a.minutes * 60 * FPS)} frames, "
                  f"{video.stat().st_size / 1e6:.1f} MB) in {time.perf_counter() - t0:.0f} s")
        if a.only != "trace":
            report(f"{a.minutes:g}-minute video ({math.floor(a.minutes * 60 * FPS)} frames)",
                   identify([str(video), "--rig", str(folder / "rig.toml"), "--camera", str(folder / "cam.toml")],
                            a.repeats))
            tracked = folder / f"tracked_{a.rows}rows.csv"
            if not tracked.exists():
                tracked_trace(video, folder / "cam.toml", tracked, a.rows)
            report(f"the video's track, {a.rows}-row trace CSV",
                   identify([str(tracked), "--rig", str(folder / "rig.toml")], a.repeats))
        if a.only != "video":
            trace = folder / f"long_{a.rows}rows.csv"
            if not trace.exists():
                real_like_trace(trace, a.rows)
            report(f"{a.rows}-row trace CSV, mostly rest",
                   identify([str(trace), "--rig", str(folder / "rig.toml")], a.repeats))

if __name__ == "__main__":
    main(sys.argv[1:])
