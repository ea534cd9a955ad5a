"""`moi camera-check` run again and again as a whole process on real videos: it must always end.

camera-check decodes the first frames and leaves the decoding early, with FFmpeg's frame-threaded decoder
still holding frames; a decoder freed in that state once deadlocked the process now and then. Each run here is
a fresh `moi camera-check VIDEO --camera CAM.toml --json` with a time limit: a run over the limit is a hang.

    .venv/bin/python bench/bench_camera_check_exit.py [RUNS] [VIDEO.mp4 ...]

RUNS (default 100) runs in all, spread over the videos (default: data/video/*.mp4, each with its camera file
NAME.toml beside it; another video needs one too). Prints, per video, the runs, the hangs, the exit statuses and
the median time of a run.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: a run longer than this (s) is counted as a hang (one run takes a few seconds on a loaded 2-core machine)
LIMIT_S = 120.0


def run_once(video: Path, out: Path) -> tuple[int | None, float]:
    """(exit status, or None when the run was stopped at the limit; seconds taken)."""
    cmd = [sys.executable, "-m", "service.cli", "camera-check", str(video), "--camera", str(video.with_suffix(".toml")),
           "--out", str(out), "--json"]
    t0 = time.perf_counter()
    try:
        done = subprocess.run(cmd, cwd=ROOT, capture_output=True, timeout=LIMIT_S)
    except subprocess.TimeoutExpired:
        return None, time.perf_counter() - t0
    return done.returncode, time.perf_counter() - t0


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else argv
    runs = int(args[0]) if args else 100
    videos = [Path(a) for a in args[1:]] or sorted((ROOT / "data" / "video").glob("*.mp4"))
    print(f"moi camera-check, {runs} whole-process runs over {len(videos)} videos, limit {LIMIT_S:g} s a run")
    with tempfile.TemporaryDirectory() as tmp:
        results: dict[Path, list[tuple[int | None, float]]] = {v: [] for v in videos}
        for k in range(runs):
            video = videos[k % len(videos)]
            results[video].append(run_once(video, Path(tmp) / "check.png"))
    total_hangs = 0
    for video, rs in results.items():
        hangs = sum(1 for code, _ in rs if code is None)
        total_hangs += hangs
        codes = Counter(code for code, _ in rs if code is not None)
        median = statistics.median(t for _, t in rs) if rs else float("nan")
        print(f"  {video.name:<28} runs {len(rs):>4}  hangs {hangs:>3}  exit statuses {dict(codes)}  "
              f"median {median:.1f} s")
    print(f"hangs: {total_hangs} of {runs}")


if __name__ == "__main__":
    main()
