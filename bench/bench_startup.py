"""Start-up: whole-process cold start of the commands that do not identify, and what they import.

    .venv/bin/python bench/bench_startup.py [--repeat 5] [--base DIR]

Each command runs ``--repeat`` times as a fresh ``python -m service.cli ...``
process (the wall time a user waits before the first line); the median is
printed with the heavy libraries the command loaded (scipy, OpenCV and
matplotlib must not be among them). ``--base DIR`` runs the same against
another source tree (e.g. an older checkout, ``git archive REV | tar -x -C DIR``)
for a before/after table on the same machine at the same load. The goal is
``moi --help`` ≤ 0.25 s on the 2-core machine of the test suite; a Raspberry Pi 4
core is 3–4 × slower.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

REPO = pathlib.Path(__file__).resolve().parents[1]

COMMANDS = (["--help"], ["results", "--help"], ["export", "--help"], ["modbus-map"])
HEAVY = ("scipy", "cv2", "matplotlib", "pymodbus", "paho", "gpiozero", "aiohttp", "numpy")

_PROBE = """
import sys
from service.cli import main
try:
    main(sys.argv[1:])
except SystemExit:
    pass
sys.stderr.write("LOADED " + " ".join(m for m in {heavy!r} if m in sys.modules) + "\\n")
"""


def _env(tree: pathlib.Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree)
    env["STATE_DIRECTORY"] = tempfile.gettempdir()  # `moi results` looks for a store; none there is fine
    return env


def cold_start(tree: pathlib.Path, argv: list[str], repeat: int) -> float:
    """Median wall time (s) of ``python -m service.cli ARGV`` as a new process."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "service.cli", *argv], env=_env(tree), cwd=tree,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def loaded(tree: pathlib.Path, argv: list[str]) -> str:
    """The heavy libraries ``ARGV`` imports."""
    out = subprocess.run([sys.executable, "-c", _PROBE.format(heavy=HEAVY), *argv], env=_env(tree), cwd=tree,
                         capture_output=True, text=True, check=False).stderr
    line = next((x for x in out.splitlines() if x.startswith("LOADED")), "LOADED ?")
    return line[len("LOADED"):].strip() or "–"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--base", metavar="DIR", help="also time this source tree (before)")
    args = ap.parse_args(argv if argv is not None else ([] if __name__ != "__main__" else None))
    trees = [("now", REPO)] + ([("base", pathlib.Path(args.base).resolve())] if args.base else [])
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = float("nan")
    print(f"cold start, median of {args.repeat} processes ({os.cpu_count()} cores, load average {load:.1f})")
    print(f"{'command':<22}" + "".join(f"{name:>10}" for name, _ in trees) + "   heavy imports (now)")
    for cmd in COMMANDS:
        times = [cold_start(tree, cmd, args.repeat) for _, tree in trees]
        label = "moi " + " ".join(cmd)
        print(f"{label:<22}" + "".join(f"{t:>9.3f}s" for t in times) + f"   {loaded(REPO, cmd)}")
    base = statistics.median(_bare(args.repeat))
    print(f"{'python -c pass':<22}{base:>9.3f}s   (the interpreter alone)")


def _bare(repeat: int) -> list[float]:
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "pass"], check=False)
        out.append(time.perf_counter() - t0)
    return out


if __name__ == "__main__":
    main()
