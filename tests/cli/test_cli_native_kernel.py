"""A one-shot command's kernels built ahead of time: the same numbers bit for bit as the in-process kernel, no numba
in the command, and one background build at a time, written down when it fails."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from measurement import Pendulum, Rig, simulate_trace
from measurement.effects import resolve_effects
from measurement.integrator import Dynamics, use_kernels
from service.cli import main
from service.commands import native
from tests.components import missing


@pytest.fixture(scope="module")
def torsion_native():
    """The torsion rig's native kernel, built in the kernel cache if it is not there yet (once per machine)."""
    if native.load(("torsion",)) is None:
        try:
            native.build("torsion")
        except Exception as exc:  # no C compiler or setuptools on this machine: the fallback is all it has
            missing(f"no native kernel can be built here (a C compiler and setuptools): {type(exc).__name__}: {exc}")
    kernels = native.load(("torsion",))
    assert kernels is not None, "the native kernel built loads"
    return kernels


@pytest.fixture
def trace_and_rig(tmp_path):
    rig = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))
    tr = simulate_trace(Pendulum(rig, 0.0125, {"viscous": {"c": 1e-4}, "coulomb": {"Tc": 1e-4}}), theta0=0.25,
                        duration=15, rate=200, noise_std=1e-4, seed=5)
    np.savetxt(tmp_path / "trace.csv", np.column_stack([tr.t, tr.angle]), delimiter=",", header="t,angle",
               comments="", fmt="%.17g")
    (tmp_path / "rig.toml").write_text('[rig]\nkind = "torsion"\nstiffness = 0.3651\n[model]\ndeclared = ["viscous"]\n')
    return ["identify", str(tmp_path / "trace.csv"), "--rig", str(tmp_path / "rig.toml"), "--json"]


@pytest.mark.parametrize(("names", "values"), [
    (("viscous",), [[3e-3]]),
    (("viscous", "coulomb"), [[2e-3], [4e-3]]),  # sticks at the end: the holding test
    (("dahl", "quadratic", "cubic_stiffness"), [[5e-3, 2e-3], [0.05], [0.4]]),  # the remembered turning point
])
def test_the_native_kernel_integrates_bit_for_bit_as_the_in_process_one(torsion_native, names, values):
    rig = Rig(kind="torsion", stiffness=0.3651, declared=names)
    dyn = Dynamics("torsion", resolve_effects(names, rig), values)
    t = np.linspace(0.0, 20.0, 4001)
    try:
        here = dyn.integrate(t, 0.3, 0.05, 5.4, 0.01)
        use_kernels(torsion_native)
        there = dyn.integrate(t, 0.3, 0.05, 5.4, 0.01)
    finally:
        use_kernels(None)
    assert np.array_equal(here[0], there[0]) and np.array_equal(here[1], there[1])
    assert np.ptp(there[0]) > 0.3  # a swing, not zeros


PROBE = """
import json, sys
from service.cli import main
status = main(sys.argv[1:])
sys.stderr.write("NUMBA:" + json.dumps("numba" in sys.modules) + "\\n")
sys.exit(status)
"""


def test_identify_with_the_native_kernel_imports_no_numba_and_gives_the_same_result(torsion_native, trace_and_rig,
                                                                                    capsys, monkeypatch):
    done = subprocess.run([sys.executable, "-c", PROBE, *trace_and_rig], capture_output=True, text=True, timeout=300,
                          check=True)
    flag = next(line for line in done.stderr.splitlines() if line.startswith("NUMBA:"))
    assert json.loads(flag[len("NUMBA:"):]) is False, "moi identify imported numba"
    monkeypatch.setattr(native, "load", lambda kinds: None)  # the in-process kernel (or its helper)
    assert main(trace_and_rig) == 0
    in_process = json.loads(capsys.readouterr().out)
    assert json.loads(done.stdout) == in_process and in_process["added_effects"] == ["coulomb"]


class _LockHolder:
    """Stands for the builder: a child that inherits the lock's descriptor and lives until its input closes."""

    def __init__(self, monkeypatch):
        self.started: list[list[str]] = []
        self.children: list[subprocess.Popen] = []
        real = subprocess.Popen

        def popen(argv, **kw):
            self.started.append(list(argv))
            kw["stdin"] = subprocess.PIPE
            self.children.append(real([sys.executable, "-c", "import sys; sys.stdin.read()"], **kw))
            return self.children[-1]
        monkeypatch.setattr(native.subprocess, "Popen", popen)

    def end(self) -> None:
        for child in self.children:
            assert child.stdin is not None
            child.stdin.close()
            child.wait(timeout=60)


def test_one_background_build_at_a_time(tmp_path, monkeypatch):
    monkeypatch.setenv("MOI_CACHE_DIR", str(tmp_path))
    holder = _LockHolder(monkeypatch)
    try:
        native.build_later(("torsion",))
        native.build_later(("torsion",))  # the first builder still holds the lock
        assert [argv[-1] for argv in holder.started] == ["torsion"]
        assert holder.started[0][1:3] == ["-m", "service.commands.native"]
    finally:
        holder.end()
    native.build_later(("torsion",))  # the builder ended without its module: a new one
    holder.end()
    assert len(holder.started) == 2


def test_a_failed_build_is_written_down_and_not_started_again(tmp_path, monkeypatch):
    monkeypatch.setenv("MOI_CACHE_DIR", str(tmp_path))

    def no_compiler(kind):
        raise OSError("no C compiler")
    monkeypatch.setattr(native, "build", no_compiler)
    assert native.main(["torsion"]) == 1
    failed = list(tmp_path.glob("*_native*.failed"))
    assert len(failed) == 1 and "no C compiler" in failed[0].read_text()
    holder = _LockHolder(monkeypatch)
    native.build_later(("torsion",))
    holder.end()
    assert holder.started == []
    assert native.load(("torsion",)) is None


def test_a_module_that_does_not_load_is_let_go_and_written_down(tmp_path, monkeypatch):
    monkeypatch.setenv("MOI_CACHE_DIR", str(tmp_path))
    broken = native.module_file("torsion")
    broken.write_bytes(b"not a shared object")  # as a module of another ABI, or on a noexec mount, fails
    broken.with_suffix(".sha256").write_text(json.dumps(native._fingerprint(broken)))  # whole, as built
    assert native.load(("torsion",)) is None
    assert not broken.exists()
    failed = list(tmp_path.glob("*_native*.failed"))
    assert len(failed) == 1 and "ImportError" in failed[0].read_text()


DAMAGED_PROBE = """
import json, sys
from service.cli import main
from service.commands import native
rebuilds = []
native.build_later = rebuilds.append  # the test looks at the cache as the command left it
status = main(sys.argv[1:])
sys.stderr.write("REBUILD:" + json.dumps(rebuilds) + "\\n")
sys.exit(status)
"""


def _cache_with_the_torsion_kernel(folder: Path) -> Path:
    """A cache folder of its own holding copies of the built torsion kernel, its record and the in-process
    kernel's source and machine code (times kept, so that numba finds its cache valid): damage stays here."""
    shared = native.module_file("torsion")
    for path in (shared, shared.with_suffix(".sha256"), shared.parent / f"{shared.name.split('_native')[0]}.py"):
        shutil.copy2(path, folder / path.name)
    if (shared.parent / "__pycache__").is_dir():
        shutil.copytree(shared.parent / "__pycache__", folder / "__pycache__", copy_function=shutil.copy2)
    return folder / shared.name


def test_a_truncated_module_is_deleted_and_the_command_still_answers(torsion_native, trace_and_rig, tmp_path,
                                                                     monkeypatch):
    cache = tmp_path / "cache"
    cache.mkdir()
    module = _cache_with_the_torsion_kernel(cache)
    monkeypatch.setenv("MOI_CACHE_DIR", str(cache))
    assert native.intact("torsion")
    # a power cut while the module was written: its headers whole, most of its code never reached the disk
    # (mapped as it is, the loader faults on the missing pages: SIGBUS, the command dead without a word)
    with module.open("r+b") as f:
        f.truncate(module.stat().st_size * 3 // 10)
    assert not native.intact("torsion")
    done = subprocess.run([sys.executable, "-c", DAMAGED_PROBE, *trace_and_rig], capture_output=True, text=True,
                          timeout=600, env={**os.environ, "MOI_CACHE_DIR": str(cache)})
    assert done.returncode == 0, (done.returncode, done.stderr[-2000:])  # not -7: SIGBUS
    assert json.loads(done.stdout)["added_effects"] == ["coulomb"]
    assert not module.exists() and not module.with_suffix(".sha256").exists(), "the damaged module is gone"
    rebuilds = next(line for line in done.stderr.splitlines() if line.startswith("REBUILD:"))
    assert json.loads(rebuilds[len("REBUILD:"):]) == [["torsion"]], "and is built again in the background"
    assert not list(cache.glob("*.failed")), "damage is not a failed build: the next build is not held back"


def test_a_module_without_its_build_record_is_not_loaded(torsion_native, tmp_path, monkeypatch):
    cache = tmp_path / "cache"
    cache.mkdir()
    module = _cache_with_the_torsion_kernel(cache)
    monkeypatch.setenv("MOI_CACHE_DIR", str(cache))
    module.with_suffix(".sha256").unlink()  # a power cut before the build wrote its record
    assert native.load(("torsion",)) is None
    assert not module.exists()


def test_a_module_of_the_right_size_but_other_bytes_is_not_loaded(torsion_native, tmp_path, monkeypatch):
    cache = tmp_path / "cache"
    cache.mkdir()
    module = _cache_with_the_torsion_kernel(cache)
    monkeypatch.setenv("MOI_CACHE_DIR", str(cache))
    data = bytearray(module.read_bytes())
    data[len(data) // 2] ^= 0xFF  # a flipped bit on the card
    module.write_bytes(bytes(data))
    assert native.load(("torsion",)) is None
    assert not module.exists()
