"""Bifilar and trifilar suspensions: the wires' exact law of the twist, J identified at large twist
without a cubic spring standing in for the geometry, and the rig file's keys."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from measurement.errors import RigError
from measurement.flags import warnings
from measurement.identification.options import Options
from measurement.identification.pipeline import identify
from measurement.reports import result_report
from measurement.restoring import amplitude_factor
from measurement.rig import Rig
from measurement.simulate import Pendulum, simulate_trace
from service.cli import main

#: a quadcopter-sized part: 1.5 kg hanging, J about the vertical axis 0.02 kg·m² (m·R²/J = 3 on the bifilar:
#: the rising part's inertia is several % of J at large twist)
MASS, INERTIA, DAMPING = 1.5, 0.02, 2e-4  # kg, kg·m², N·m·s/rad
RIGS = {
    "bifilar": {"kind": "bifilar", "mass": MASS, "wire_length": 1.0, "spacing": 0.4},
    "trifilar": {"kind": "trifilar", "mass": MASS, "wire_length": 0.8, "radius": 0.15},
}


def rig_of(kind: str) -> Rig:
    return Rig.from_dict({"rig": RIGS[kind]})


def three_d_swing(rig: Rig, t: np.ndarray, theta0: float) -> np.ndarray:
    """The swing from the wires' 3-D constraint, written independently of the library's law: the part's depth
    below a wire's upper end, differentiated numerically, in the Lagrangian ½J·θ'² + ½m·ż² + m·g·z."""
    R, L, m, g = rig.wire_radius, rig.wire_length, rig.mass, rig.g
    assert R is not None and L is not None and m is not None
    top = np.array([R, 0.0, 0.0])

    def depth(th: float) -> float:
        lower = np.array([R * math.cos(th), R * math.sin(th)])
        return math.sqrt(L**2 - float(np.sum((lower - top[:2]) ** 2)))

    def rhs(_t: float, y: np.ndarray) -> list[float]:
        th, v = y
        h = 1e-4  # the second difference's truncation (1e-8) above its rounding (1e-8 / h²·1e-16)
        zp = (depth(th + h) - depth(th - h)) / (2 * h)
        zpp = (depth(th + h) - 2 * depth(th) + depth(th - h)) / h**2
        return [v, (m * g * zp - m * zp * zpp * v * v - DAMPING * v) / (INERTIA + m * zp * zp)]

    return solve_ivp(rhs, (t[0], t[-1]), [theta0, 0.0], t_eval=t, rtol=1e-9, atol=1e-10).y[0]


@pytest.mark.parametrize("kind", sorted(RIGS))
def test_the_law_is_the_wires_geometry(kind):
    rig = rig_of(kind)
    t = np.linspace(0.0, 15.0, 1501)
    theta0 = math.radians(80)
    swing, _ = Pendulum(rig, INERTIA, {"viscous": {"c": DAMPING}}).motion(t, theta0)
    assert np.max(np.abs(swing - three_d_swing(rig, t, theta0))) < 1e-5  # rad, 1.4 rad swing


def test_small_swing_constant_is_the_textbook_one():
    rig = rig_of("bifilar")
    m, g, D, L = MASS, rig.g, 0.4, 1.0  # the bifilar's spacing and wire length
    assert rig.restoring_constant == pytest.approx(m * g * D**2 / (4 * L), rel=1e-12)
    tri = rig_of("trifilar")
    assert tri.restoring_constant == pytest.approx(m * g * 0.15**2 / 0.8, rel=1e-12)
    assert Rig.from_dict(rig.to_dict()) == rig and Rig.from_dict(tri.to_dict()) == tri  # `moi calibrate --out` writes it


@pytest.mark.parametrize("kind", sorted(RIGS))
def test_period_at_amplitude_is_the_simulated_one(kind):
    rig = rig_of(kind)
    p = Pendulum(rig, INERTIA)
    theta0 = math.radians(70)
    t = np.linspace(0.0, 12.0, 120_001)
    swing, _ = p.motion(t, theta0)
    down = np.flatnonzero((swing[:-1] > 0) & (swing[1:] <= 0))
    crossings = t[down] - swing[down] * (t[down + 1] - t[down]) / (swing[down + 1] - swing[down])
    period = float(np.mean(np.diff(crossings)))
    expected = 2 * math.pi / p.omega_n * amplitude_factor(kind, theta0, p.omega_n, rig.geometry)
    assert period == pytest.approx(expected, rel=2e-5)
    assert period > 2 * math.pi / p.omega_n * 1.02  # the geometry does soften: a plain k·θ is wrong here


@pytest.mark.parametrize("kind", sorted(RIGS))
@pytest.mark.parametrize("degrees", [40, 80])
def test_large_twist_gives_j_without_a_cubic_spring(kind, degrees):
    rig = rig_of(kind)
    trace = simulate_trace(Pendulum(rig, INERTIA, {"viscous": {"c": DAMPING}}), theta0=math.radians(degrees),
                           duration=40.0, rate=100.0, noise_std=1e-3, seed=degrees)
    r = identify(trace, rig, Options())
    assert r.J is not None and abs(r.J / INERTIA - 1) < 2e-3
    assert "cubic_stiffness" not in r.effects
    assert not warnings(r.flags)
    # the period at the record's swing is the geometry's, beside the small-swing one
    assert r.periods is not None and r.periods.at_amplitude > r.periods.small_swing


def test_a_torsion_rig_standing_in_for_a_bifilar_misses_j():
    """What the law is for: the same swing read as a torsion rig of k = m·g·D²/(4L) is off by far more than 0.2 %."""
    rig = rig_of("bifilar")
    trace = simulate_trace(Pendulum(rig, INERTIA, {"viscous": {"c": DAMPING}}), theta0=math.radians(60),
                           duration=40.0, rate=100.0, noise_std=1e-3, seed=1)
    assert rig.restoring_constant is not None
    r = identify(trace, Rig(kind="torsion", stiffness=rig.restoring_constant), Options(focused=False))
    assert r.J is not None and abs(r.J / INERTIA - 1) > 0.01


@pytest.mark.parametrize(("rig", "expected"), [
    ({"kind": "bifilar", "mass": 1.0, "spacing": 0.4}, "needs wire_length (m) and spacing (m)"),
    ({"kind": "trifilar", "mass": 1.0, "wire_length": 1.0, "spacing": 0.4}, "spacing (the wires' spacing D) belongs "
                                                                         "to a bifilar rig; kind is 'trifilar'"),
    ({"kind": "bifilar", "wire_length": 1.0, "spacing": -0.4}, "spacing must be > 0 m"),
    ({"kind": "bifilar", "wire_length": 1.0, "spacing": "40 cm"}, "spacing must be a number in m"),
    ({"kind": "bifilar", "wire_length": 0.1, "spacing": 0.4}, "wires must be longer than their distance"),
    ({"kind": "torsion", "stiffness": 0.3, "wire_length": 1.0}, "wire_length belongs to a bifilar or trifilar rig"),
    ({"kind": "bifilar", "stiffness": 0.3, "wire_length": 1.0, "spacing": 0.4}, "stiffness (k) belongs to a torsion"),
])
def test_a_bad_rig_file_is_one_line(tmp_path, capsys, rig, expected):
    with pytest.raises(RigError, match=expected.replace("(", r"\(").replace(")", r"\)")):
        Rig.from_dict({"rig": rig})
    path = tmp_path / "rig.toml"
    path.write_text("[rig]\n" + "".join(f"{k} = {v!r}\n".replace("'", '"') for k, v in rig.items()))
    swing = tmp_path / "swing.csv"
    swing.write_text("t,angle\n" + "".join(f"{i * 0.01},{0.3 * math.cos(i * 0.05)}\n" for i in range(400)))
    assert main(["identify", str(swing), "--rig", str(path)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0]


def test_the_budget_takes_the_geometry_and_a_rig_without_mass_gives_omega_n():
    rig = Rig.from_dict({"rig": dict(RIGS["bifilar"], mass_std=0.001, spacing_std=0.0005)})
    trace = simulate_trace(Pendulum(rig, INERTIA, {"viscous": {"c": DAMPING}}), theta0=math.radians(60),
                           duration=30.0, rate=100.0, noise_std=1e-3, seed=5)
    r = identify(trace, rig, Options())
    budget = r.uncertainty_budget["J"]
    lines = {line.symbol: line for line in budget.lines}
    # J = m·g·R²/(L·ω²): ∂J/∂R = 2J/R, R = D/2 with σ_D/2
    assert lines["R"].sensitivity == pytest.approx(2 * INERTIA / 0.2, rel=1e-3)
    assert lines["R"].std == pytest.approx(0.00025)
    bare = Rig.from_dict({"rig": {k: v for k, v in RIGS["bifilar"].items() if k != "mass"}})
    r_bare = identify(trace, bare, Options())
    assert r_bare.J is None and r_bare.omega_n == pytest.approx(r.omega_n, rel=1e-9)
    assert "mass (bifilar, trifilar)" in result_report(r_bare)
