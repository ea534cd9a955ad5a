"""Cold start: the wall time a technician waits for one command, as a whole process, before and after.

    .venv/bin/python bench/bench_cold_start.py [--repeat 5] [--no-before] [--before REV]

* `moi identify` of a 30 s, 200 Hz trace (torsion rig, declared viscous): goal ≤ 0.6 s;
* `moi --help`: goal ≤ 0.1 s.

Each figure is the median of ``--repeat`` fresh ``python -m service.cli`` processes, before and
after alternating so that both see the same load; "one core" pins the process with
``taskset -c 0`` (the proxy for one Raspberry Pi core, which is 3–4 × slower still). "before" is
the source tree at BEFORE (the last commit that imported scipy.signal for its smoothing and
loaded every publisher's library with the configuration), or at ``--before REV``, unpacked with
`git archive`. Every run finds what a device has after its first measurement: the integration
kernel compiled (numba's on-disk cache) and, in a tree that has them, the kernels built ahead of time
(``service.commands.native``: `moi identify` then imports no numba), both built before the timed
runs; and the modules' bytecode cached (in a folder of the bench's own, ``PYTHONPYCACHEPREFIX``:
an environment with ``PYTHONDONTWRITEBYTECODE`` would otherwise compile every module of the tree
from source in every run, ~0.2 s). Without its native kernel, `moi identify` loads numba in a helper
process on a second core (``service.commands.kernels``) when a core is idle: its CPU time is counted
with the command's. Run it on an idle machine. The CPU time (user + system) is what a busy machine
does not inflate as it does the wall time.
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

GOALS = {"identify": 0.6, "help": 0.1}
RIG_TOML = '[rig]\nkind = "torsion"\nstiffness = 0.3651\n[model]\ndeclared = ["viscous"]\n'


def _env(tree: Path, pycache: Path) -> dict[str, str]:
    """The tree on the path, its bytecode cached in ``pycache`` (in the bench's work folder), as a device caches it."""
    env = dict(os.environ, PYTHONPATH=str(tree), PYTHONPYCACHEPREFIX=str(pycache))
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def _build_native(tree: Path, env: dict[str, str], kind: str) -> None:
    """Build the tree's ahead-of-time kernel, when it has them, as the first command on a device starts it."""
    if (tree / "service" / "commands" / "native.py").exists():
        subprocess.run([sys.executable, "-m", "service.commands.native", kind], env=env, cwd=tree, check=True)


def _command(tree: Path, env: dict[str, str], argv: list[str], pin: bool) -> tuple[float, float]:
    """Wall and CPU time (s) of one process."""
    cmd = [sys.executable, "-m", "service.cli", *argv]
    if pin:
        cmd = ["taskset", "-c", "0", *cmd]
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
        envs = {name: _env(tree, work / f"pycache-{name}") for name, tree in trees}
        for name, tree in trees:  # fills the kernel and bytecode caches: every timed run only loads them
            _build_native(tree, envs[name], "torsion")
            _command(tree, envs[name], commands["identify"], False)
            _command(tree, envs[name], commands["help"], False)
        times: dict[tuple[str, str, bool], list[tuple[float, float]]] = {}
        for _ in range(args.repeat):
            for key, argv_ in commands.items():
                for pin in pins:
                    for name, tree in trees:
                        times.setdefault((name, key, pin), []).append(_command(tree, envs[name], argv_, pin))
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
