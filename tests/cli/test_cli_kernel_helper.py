"""A one-shot command's kernels in a helper process: the same compiled kernel, so the same numbers bit for bit;
and the command goes on with the in-process kernel when the helper is gone."""

from __future__ import annotations

import json

import numpy as np
import pytest

from measurement import Pendulum, Rig, simulate_trace
from measurement.effects import resolve_effects
from measurement.integrator import Dynamics, use_kernels, warm_up
from service.cli import main
from service.commands import kernels, native


@pytest.fixture
def helper():
    warm_up("compound")  # the helper serves compiled kernels only
    h = kernels.KernelHelper(("compound",))
    yield h
    use_kernels(None)
    h.close()


def _swing(params: Dynamics) -> tuple[np.ndarray, np.ndarray]:
    return params.integrate(np.linspace(0.0, 6.0, 1201), 0.4, 0.0, 5.2, 0.01)


def test_the_helpers_kernel_integrates_bit_for_bit_as_the_in_process_one(helper):
    rig = Rig(kind="compound", mass=1.2, com_distance=0.15, declared=("viscous", "coulomb"))
    effects = resolve_effects(("viscous", "coulomb"), rig)
    dyn = Dynamics("compound", effects, [[2e-3], [4e-3]])
    here = _swing(dyn)
    use_kernels(helper)
    there = _swing(dyn)
    assert helper._proc is not None, "the helper answered"
    assert np.array_equal(here[0], there[0]) and np.array_equal(here[1], there[1])
    assert np.ptp(there[0]) > 0.5  # a swing, not zeros


def test_without_its_helper_the_command_integrates_in_process(helper):
    dyn = Dynamics("compound", (), ())
    expected = _swing(dyn)
    use_kernels(helper)
    assert helper._proc is not None
    helper._proc.kill()
    helper._proc.wait()
    got = _swing(dyn)
    assert helper._proc is None, "the dead helper is let go"
    assert np.array_equal(got[0], expected[0]) and np.array_equal(got[1], expected[1])


def test_identify_gives_the_same_result_with_and_without_the_helper(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(kernels, "spare_core", lambda: True)  # the machine may be busy: the helper anyway
    monkeypatch.setattr(native, "load", lambda kinds: None)  # and the kernel built ahead of time is not used
    rig = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))
    warm_up("torsion")
    tr = simulate_trace(Pendulum(rig, 0.0125, {"viscous": {"c": 1e-4}, "coulomb": {"Tc": 1e-4}}), theta0=0.25,
                        duration=15, rate=200, noise_std=1e-4, seed=5)
    np.savetxt(tmp_path / "trace.csv", np.column_stack([tr.t, tr.angle]), delimiter=",", header="t,angle",
               comments="", fmt="%.17g")
    (tmp_path / "rig.toml").write_text('[rig]\nkind = "torsion"\nstiffness = 0.3651\n[model]\ndeclared = ["viscous"]\n')
    argv = ["identify", str(tmp_path / "trace.csv"), "--rig", str(tmp_path / "rig.toml"), "--json"]
    started: list[kernels.KernelHelper | None] = []
    real_start = kernels.start

    def start(kinds):
        started.append(real_start(kinds))
        return started[-1]
    monkeypatch.setattr(kernels, "start", start)
    assert main(argv) == 0
    with_helper = json.loads(capsys.readouterr().out)
    monkeypatch.setattr(kernels, "start", lambda kinds: None)
    assert main(argv) == 0
    without = json.loads(capsys.readouterr().out)
    assert started and started[0] is not None, "the command started its helper"
    assert with_helper == without and with_helper["added_effects"] == ["coulomb"]


def test_no_helper_without_a_spare_core(monkeypatch):
    monkeypatch.setattr(kernels, "spare_core", lambda: False)
    assert kernels.start(("torsion",)) is None
