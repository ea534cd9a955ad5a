"""A result within a second of the swing's end on a Raspberry Pi: speed, scale and memory, before and after.

    .venv/bin/python bench/bench_speed.py [--repeat 5] [--quick] [--no-before]

"before" is the source tree at BEFORE (the last commit whose integrator was
pure Python with a difference Jacobian of one simulation per parameter and
whose candidate fits ran one after the other), unpacked with `git archive`;
"after" is this tree. Every number comes from fresh processes that alternate
before/after on the same machine at the same load, on the same traces (made
once here and written to CSV):

* identification with discovery of a 30 s, 200 Hz trace (torsion rig,
  declared viscous, dry friction in the truth): median wall time on all cores
  and pinned to one core (`taskset -c 0`, the proxy for one Pi 4 core), and
  the CPU time, which a busy machine does not inflate as it does the wall time;
* the declared-model fit of the same trace;
* the scaling of the whole identification with discovery: 10, 30, 100 and
  300 s at 200 Hz, and 30 s from a 1 kHz encoder;
* a cold `moi identify` process (imports, the compiled kernel's load);
* `moi --help` cold start (bench_startup.cold_start);
* the daemon's resident memory after 100 simulated measurements.

In-process times exclude the first call of a process (imports, the kernel's
load from the on-disk cache; its compilation on the very first run of a
device): the cold process line shows those. Goals on the 2-core machine of
the tests: discovery ≤ 0.25 s all cores and ≤ 0.4 s one core, declared fit
≤ 0.05 s, `moi --help` ≤ 0.25 s, 300 s ≤ 10 × the 30 s time.
"""

from __future__ import annotations

import argparse
import json
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
REPO = HERE.parent
BEFORE = "ed94edd2941fd79bff743218b83ead5d3f0aefd9"

K, J = 0.3651, 0.0125
TRUTH = {"viscous": {"c": 1e-4}, "coulomb": {"Tc": 1.5e-4}}
RIG_TOML = f'[rig]\nkind = "torsion"\nstiffness = {K}\n[model]\ndeclared = ["viscous"]\n'
SCALING = [(10, 200), (30, 200), (100, 200), (300, 200), (30, 1000)]


# -- the worker: runs inside the tree under test ------------------------------------


def _worker(args: argparse.Namespace) -> None:
    """Time identify() on a trace CSV; print one JSON line."""
    import numpy as np

    from measurement import Options, Rig, Trace, identify

    data = np.loadtxt(args.trace, delimiter=",", skiprows=1)
    trace = Trace(data[:, 0], data[:, 1], source=Path(args.trace).name)
    rig = Rig(kind="torsion", stiffness=K, declared=("viscous",))
    options = Options(discover=bool(args.discover))
    t0 = time.perf_counter()
    first = identify(trace, rig, options) if args.warmup else None
    first_call = time.perf_counter() - t0
    walls, cpus, r = [], [], first
    for _ in range(args.repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        r = identify(trace, rig, options)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    print(json.dumps({"wall": walls, "cpu": cpus, "first_call": first_call if args.warmup else None,
                      "nfev": r.statistics["nfev"], "J": r.J, "added": list(r.added_effects)}))


def _daemon_worker(args: argparse.Namespace) -> None:
    """Run the appliance on the simulated rig for ``args.count`` measurements; print RSS as JSON."""
    import logging
    import threading

    os.environ.setdefault("GPIOZERO_PIN_FACTORY", "mock")
    logging.basicConfig(level=logging.ERROR)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    from _appliance import Finished, simulated_doc
    try:
        from service.config.appliance import parse_config
    except ImportError:  # "before" is a tree from when the configuration was one module
        from service.config import parse_config  # type: ignore[attr-defined,no-redef]
    from service.daemon import Appliance

    work = Path(tempfile.mkdtemp(prefix="moi-bench-rss-"))
    doc = simulated_doc(work / "state", log_level="error")
    app = Appliance(parse_config(doc, source="bench"), poll_interval=0.02)
    app.start()
    loop = threading.Thread(target=app.run, daemon=True)
    loop.start()
    finished = Finished(app)
    rss = {}
    t0 = time.perf_counter()
    for i in range(1, args.count + 1):
        faults = finished.faults
        app.command("trigger", "bench")
        if not finished.wait(i, 120):
            break
        if finished.faults > faults:
            app.command("abort", "bench")  # FAULT is latched: clear it for the next one
        if i in (1, 10) or i % 25 == 0:
            rss[i] = [_status_kb("VmRSS"), _status_kb("RssAnon")]
    wall = time.perf_counter() - t0
    app.request_stop()
    loop.join(30)
    shutil.rmtree(work, ignore_errors=True)
    print(json.dumps({"rss_kb": rss, "peak_kb": _status_kb("VmHWM"), "done": finished.count, "wall": wall,
                      "faults": finished.fault_reasons}))


def _status_kb(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    return -1


# -- the parent: makes the traces, unpacks "before", alternates the trees ------------


def _before_tree(work: Path, rev: str = BEFORE) -> Path | None:
    """The source tree at ``rev`` unpacked in ``work``/before (None without git or the commit)."""
    tree = work / "before"
    tree.mkdir()
    try:
        archive = subprocess.run(["git", "-C", str(REPO), "archive", rev, "measurement", "service", "drivers",
                                  "firmware_host"], capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    except (OSError, subprocess.CalledProcessError):
        return None
    return tree


def _env(tree: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree)
    return env


def _run(tree: Path, argv: list[str], pin: bool = False) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), *argv]
    if pin:
        cmd = ["taskset", "-c", "0", *cmd]
    out = subprocess.run(cmd, env=_env(tree), cwd=tree, capture_output=True, text=True, check=False)
    line = next((x for x in reversed(out.stdout.splitlines()) if x.startswith("{")), None)
    if line is None:
        raise RuntimeError(f"worker failed in {tree}: {out.stderr.strip().splitlines()[-1:]}")
    return json.loads(line)


def _identify(tree: Path, trace: Path, *, discover: bool = True, repeat: int = 3, pin: bool = False,
              warmup: bool = True) -> dict:
    return _run(tree, ["--worker", "--trace", str(trace), "--discover", str(int(discover)),
                       "--repeat", str(repeat), "--warmup", str(int(warmup))], pin=pin)


def _make_trace(work: Path, duration: float, rate: float) -> Path:
    import numpy as np

    from measurement import Pendulum, Rig, simulate_trace

    rig = Rig(kind="torsion", stiffness=K, declared=("viscous",))
    tr = simulate_trace(Pendulum(rig, J, TRUTH), theta0=0.25, duration=duration, rate=rate, noise_std=1e-4,
                        quantisation_bits=17, seed=11)
    path = work / f"trace_{duration:g}s_{rate:g}Hz.csv"
    np.savetxt(path, np.column_stack([tr.t, tr.angle]), delimiter=",", header="t,angle", comments="", fmt="%.17g")
    return path


def _cold_identify(tree: Path, trace: Path, rig: Path, repeat: int) -> tuple[float, float]:
    """Median wall and CPU time (s) of a whole `moi identify` process."""
    walls, cpus = [], []
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "service.cli", "identify", str(trace), "--rig", str(rig), "--json"],
                       env=_env(tree), cwd=tree, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
        walls.append(time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
    return statistics.median(walls), statistics.median(cpus)


def _med(xs: list[float]) -> float:
    return statistics.median(xs) if xs else float("nan")


def _merge(runs: list[dict]) -> dict:
    """Several worker runs of the same case as one: all their timings, the last facts."""
    out = dict(runs[-1])
    out["wall"] = [w for r in runs for w in r["wall"]]
    out["cpu"] = [c for r in runs for c in r["cpu"]]
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="timed calls per case (after)")
    ap.add_argument("--quick", action="store_true", help="no 300 s and 1 kHz rows, 25 daemon measurements")
    ap.add_argument("--no-before", action="store_true", help="time this tree only")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--daemon", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--trace", help=argparse.SUPPRESS)
    ap.add_argument("--discover", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--warmup", type=int, default=1, help=argparse.SUPPRESS)
    args = ap.parse_args(argv if argv is not None else ([] if __name__ != "__main__" else None))
    if args.worker:
        args.repeat = max(args.repeat, 1)
        return _worker(args)
    if args.daemon:
        args.count = args.daemon
        return _daemon_worker(args)

    sys.path.insert(0, str(REPO))
    work = Path(tempfile.mkdtemp(prefix="moi-bench-speed-"))
    try:
        _report(args, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _report(args: argparse.Namespace, work: Path) -> None:
    sys.path.insert(0, str(HERE))
    from bench_startup import cold_start

    before = None if args.no_before else _before_tree(work)
    trees = [("after", REPO)] + ([("before", before)] if before else [])
    has_taskset = shutil.which("taskset") is not None
    load = os.getloadavg()[0]
    print(f"{os.cpu_count()} cores, load average {load:.1f} at the start (wall times on a busy machine are "
          f"inflated; CPU time is not); before = {BEFORE[:10]}" + ("" if before else " (not available)"))
    trace30 = _make_trace(work, 30, 200)
    rig = work / "rig.toml"
    rig.write_text(RIG_TOML)
    n = args.repeat

    # 1. 30 s @ 200 Hz, discovery, all cores and one core; declared fit. Interleaved before/after.
    rows: dict[tuple[str, str], list[dict]] = {}
    for _ in range(2):
        for name, tree in trees:
            reps = n if name == "after" else max(1, n // 3)
            rows.setdefault((name, "all"), []).append(_identify(tree, trace30, repeat=reps, warmup=name == "after"))
            if has_taskset:
                rows.setdefault((name, "one"), []).append(
                    _identify(tree, trace30, repeat=reps, pin=True, warmup=name == "after"))
            rows.setdefault((name, "declared"), []).append(
                _identify(tree, trace30, discover=False, repeat=reps, warmup=name == "after"))
    print("\n30 s at 200 Hz (6000 samples), torsion, declared viscous, dry friction in the truth")
    print(f"{'':34}{'after':>22}{'before':>22}{'goal':>9}")
    print(f"{'':34}{'wall    CPU   sims':>22}{'wall    CPU   sims':>22}")
    goals = {"all": 0.25, "one": 0.4, "declared": 0.05}
    labels = {"all": "discovery, all cores", "one": "discovery, one core (taskset -c 0)",
              "declared": "declared-model fit"}
    for case in ("all", "one", "declared"):
        cells = ""
        for name, _ in trees:
            if (name, case) not in rows:
                cells += f"{'–':>22}"
                continue
            r = _merge(rows[(name, case)])
            cells += f"{_med(r['wall']):>7.3f}s{_med(r['cpu']):>6.3f}s{r['nfev']:>6d}"
        print(f"{labels[case]:<34}{cells}{goals[case]:>8.2f}s")
    after = _merge(rows[("after", "all")])
    print(f"  added: {','.join(after['added']) or '-'}, J error {1e6 * (after['J'] / J - 1):+.1f} ppm"
          + ("" if not before else f" (before: {','.join(_merge(rows[('before', 'all')])['added']) or '-'}, "
                                   f"{1e6 * (_merge(rows[('before', 'all')])['J'] / J - 1):+.1f} ppm)"))
    print(f"  first call of a process (imports, compiled kernel loaded from the cache): "
          f"{after['first_call']:.2f} s")

    # 2. scaling
    scaling = SCALING if not args.quick else SCALING[:3]
    print("\nscaling of identification with discovery (median wall / CPU; sims = simulations)")
    print(f"{'record':<18}{'samples':>8}" + "".join(f"{name + ' wall':>14}{'CPU':>8}{'sims':>6}" for name, _ in trees))
    per = {}
    for duration, rate in scaling:
        path = trace30 if (duration, rate) == (30, 200) else _make_trace(work, duration, rate)
        line = f"{f'{duration:g} s @ {rate:g} Hz':<18}{int(duration * rate):>8}"
        for name, tree in trees:
            r = _identify(tree, path, repeat=3 if name == "after" else 1, warmup=name == "after")
            per[(name, duration, rate)] = r
            line += f"{_med(r['wall']):>13.3f}s{_med(r['cpu']):>7.3f}s{r['nfev']:>6d}"
        print(line, flush=True)
    for name, _ in trees:
        if (name, 300, 200) in per:
            a, b = per[(name, 300, 200)], per[(name, 30, 200)]
            print(f"  {name}: 300 s / 30 s = {_med(a['cpu']) / _med(b['cpu']):.1f} × in CPU, "
                  f"{_med(a['wall']) / _med(b['wall']):.1f} × in wall (goal ≤ 10 ×; the record is 10 × longer)")

    # 3. cold processes
    print("\ncold start, whole process (median of 3; `moi --help` of 5)")
    print(f"{'':36}" + "".join(f"{name + ' wall':>13}{'CPU':>8}" for name, _ in trees))
    cells = ""
    for _, tree in trees:
        w, c = _cold_identify(tree, trace30, rig, 3)
        cells += f"{w:>12.2f}s{c:>7.2f}s"
    print(f"{'moi identify 30 s @ 200 Hz --json':<36}{cells}")
    print(f"{'moi --help (goal ≤ 0.25 s)':<36}" + "".join(f"{cold_start(tree, ['--help'], 5):>12.3f}s{'':>8}"
                                                          for _, tree in trees))

    # 4. daemon memory
    count = 25 if args.quick else 100
    print(f"\ndaemon resident memory after n of {count} simulated measurements (5 s swings at 100 Hz, time × 25): "
          "n: RSS (of it anonymous, the rest is mapped library code the kernel can drop), MB")
    for name, tree in trees:
        try:
            r = _run(tree, ["--daemon", str(count)])
        except RuntimeError as exc:
            print(f"  {name}: {exc}")
            continue
        rss = "  ".join(f"{k}: {v[0] / 1024:.0f} ({v[1] / 1024:.0f})" for k, v in r["rss_kb"].items())
        faults = r.get("faults") or []
        print(f"  {name:<7}{rss}; peak {r['peak_kb'] / 1024:.0f} MB ({r['done']} measurements in {r['wall']:.0f} s"
              + (f", {len(faults)} ended in FAULT: {faults[0]}" if faults else "") + ")")


if __name__ == "__main__":
    main()
