"""Cold start: the wall time a technician waits for one command, as a whole process, before and after.

    .venv/bin/python bench/bench_cold_start.py [--repeat 5] [--no-before] [--before REV]

* `moi identify` of a 30 s, 200 Hz trace (torsion rig, declared viscous): goal ≤ 0.7 s;
* `moi --help`: goal ≤ 0.1 s.

Each figure is the median of ``--repeat`` fresh ``python -m service.cli`` processes, before and
after alternating so that both see the same load; "one core" pins the process with
``taskset -c 0`` (the proxy for one Raspberry Pi core, which is 3–4 × slower still). "before" is
the source tree at BEFORE (the last commit that imported scipy.signal for its smoothing and
loaded every publisher's library with the configuration), or at ``--before REV``, unpacked with
`git archive`. `moi identify` loads its integration kernel in a helper process on a second core
(``service.commands.kernels``) when a core is idle: its CPU time is counted with the command's;
pinned to one core, or with no core idle, the command runs without it. Run it on an idle machine. The
compiled integration kernel is loaded from the on-disk cache in every timed run (one untimed run
first fills it), as on a device after its first measurement. The CPU time (user + system) is what a
busy machine does not inflate as it does the wall time.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # the benches' shared helpers

from bench_speed import _before_tree  # noqa: E402

REPO = HERE.parent
BEFORE = "b622b1d"

GOALS = {"identify": 0.7, "help": 0.1}
RIG_TOML = '[rig]\nkind = "torsion"\nstiffness = 0.3651\n[model]\ndeclared = ["viscous"]\n'


def _command(tree: Path, argv: list[str], pin: bool) -> tuple[float, float]:
    """Wall and CPU time (s) of one process."""
    cmd = [sys.executable, "-m", "service.cli", *argv]
    if pin:
        cmd = ["taskset", "-c", "0", *cmd]
    env = dict(os.environ, PYTHONPATH=str(tree))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(cmd, env=env, cwd=tree, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                          check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} in {tree}: {done.stderr.strip().splitlines()[-1:]}")
    return wall, after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--no-before", action="store_true", help="time this tree only")
    ap.add_argument("--before", default=BEFORE, metavar="REV", help=f"the commit to compare with (default {BEFORE})")
    args = ap.parse_args(argv if argv is not None else ([] if __name__ != "__main__" else None))
    sys.path.insert(0, str(REPO))
    import numpy as np

    from measurement import Pendulum, Rig, simulate_trace

    work = Path(tempfile.mkdtemp(prefix="moi-bench-cold-"))
    try:
        rig = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))
        tr = simulate_trace(Pendulum(rig, 0.0125, {"viscous": {"c": 1e-4}}), theta0=0.25, duration=30, rate=200,
                            noise_std=1e-4, quantisation_bits=17, seed=11)
        trace = work / "trace.csv"
        np.savetxt(trace, np.column_stack([tr.t, tr.angle]), delimiter=",", header="t,angle", comments="",
                   fmt="%.17g")
        (work / "rig.toml").write_text(RIG_TOML)
        commands = {"identify": ["identify", str(trace), "--rig", str(work / "rig.toml")], "help": ["--help"]}
        before = None if args.no_before else _before_tree(work, args.before)
        trees = [("after", REPO)] + ([("before", before)] if before else [])
        pins = [False] + ([True] if shutil.which("taskset") else [])
        for _, tree in trees:  # fills the kernel cache: every timed run only loads it
            _command(tree, commands["identify"], False)
        times: dict[tuple[str, str, bool], list[tuple[float, float]]] = {}
        for _ in range(args.repeat):
            for key, argv_ in commands.items():
                for pin in pins:
                    for name, tree in trees:
                        times.setdefault((name, key, pin), []).append(_command(tree, argv_, pin))
        load = os.getloadavg()[0]
        print(f"cold start, whole process, median of {args.repeat} ({os.cpu_count()} cores, load average {load:.1f}); "
              f"before = {args.before}" + ("" if before else " (not available)"))
        print(f"{'':44}" + "".join(f"{name + ' wall':>13}{'CPU':>8}" for name, _ in trees) + f"{'goal':>8}")
        for key in commands:
            for pin in pins:
                label = ("moi identify 30 s @ 200 Hz" if key == "identify" else "moi --help") + \
                        (", one core" if pin else "")
                cells = "".join(f"{statistics.median(w for w, _ in times[(name, key, pin)]):>12.3f}s"
                                f"{statistics.median(c for _, c in times[(name, key, pin)]):>7.3f}s" for name, _ in trees)
                print(f"{label:<44}{cells}{GOALS[key]:>7.2f}s")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
