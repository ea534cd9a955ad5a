"""The simulator against exact solutions."""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from measurement import Pendulum, Rig, simulate_trace
from measurement.effects import EFFECTS
from measurement.errors import InvalidInput

# Hou Wen, "Measuring Moment of Inertia Based on Identification of Nonlinear System Featuring Naught Excitation" (WSEAS, 2006), Fig. 3
G, J, MU, M, S, K, PHI0 = 9.8, 1000.0, 0.01, 500.0, 1.0, 10.0, -0.5


def phase_plane_u(x, x0, direction, a, b, c):
    """Hou Wen (WSEAS 2006) eq. 13/14: y² = φ'² on the half-swing that starts at rest at x0.

    With u = y² the equation is linear in u: du/dx = −2a·sin x − 2b·cos x − 2c·u for y ≥ 0 (the b and c
    terms flip sign for y < 0), a = m·g·S/J, b = μ·m·g/J, c = K/J; p1 = a − 2bc, p2 = 2ac + b, p3 = 2c² + 0.5.
    """
    b, c = b * direction, c * direction
    p1, p2, p3 = a - 2 * b * c, 2 * a * c + b, 2 * c * c + 0.5
    part = lambda xx: (p1 * np.cos(xx) - p2 * np.sin(xx)) / p3  # noqa: E731
    const = -part(x0) * np.exp(2 * c * x0)
    return part(x) + const * np.exp(-2 * c * x)


def test_simulator_matches_the_exact_phase_plane_solution_to_1e_6():
    rig = Rig(kind="compound", mass=M, com_distance=S, g=G)
    pendulum = Pendulum(rig, J, {"coulomb": {"mu": MU}, "quadratic": {"K": K}})
    a, b, c = M * G * S / J, MU * M * G / J, K / J
    t = np.arange(0.0, 40.0, 1 / 200)
    x, v = pendulum.motion(t, PHI0)
    # half-swings of the simulation: runs of constant velocity sign
    sign = np.sign(v)
    runs, start = [], 1
    for i in range(2, sign.size):
        if sign[i] != sign[i - 1]:
            runs.append((start, i))
            start = i
    x0, direction, worst, checked = PHI0, 1.0, 0.0, 0
    for i0, i1 in runs:
        if sign[i0] == 0:
            break  # stuck
        assert sign[i0] == direction
        u = lambda xx: phase_plane_u(xx, x0, direction, a, b, c)  # noqa: E731
        grid = np.linspace(x0, -x0, 4001)[1:]
        j = np.flatnonzero(u(grid) <= 0)[0]
        x1 = brentq(u, grid[j - 1], grid[j])  # exact next turning point ("sewing")
        exact = u(x[i0:i1])
        worst = max(worst, float(np.max(np.abs(v[i0:i1] ** 2 - exact)) / np.max(exact)))
        checked += 1
        x0, direction = x1, -direction
    assert checked >= 20
    assert worst < 1e-6
    # it comes to rest where the exact solution says static friction holds it
    assert abs(a * math.sin(x0)) <= b * math.cos(x0)
    assert x[-1] == pytest.approx(x0, abs=1e-9)


def test_viscous_torsion_matches_closed_form():
    rig = Rig(kind="torsion", stiffness=0.3651)
    c, inertia, theta0 = 2e-4, 0.01, 0.3
    pendulum = Pendulum(rig, inertia, {"viscous": {"c": c}})
    t = np.linspace(0, 30, 3001)
    x, _ = pendulum.motion(t, theta0)
    sigma = c / (2 * inertia)
    assert rig.stiffness is not None
    wd = math.sqrt(rig.stiffness / inertia - sigma**2)
    exact = theta0 * np.exp(-sigma * t) * (np.cos(wd * t) + sigma / wd * np.sin(wd * t))
    # RK4 at ω·h ≤ 0.05: phase error ~1e-6 rad after 180 rad of swing (J bias ~1e-8)
    assert np.max(np.abs(x - exact)) < 3e-6 * theta0


def test_coulomb_torsion_sticks_where_piecewise_solution_says():
    # Each half-swing of k·θ + T·s is a harmonic swing about ∓T/k: the amplitude
    # about the origin drops by 2T/k per half-swing until |θ| ≤ T/k.
    k, inertia, torque, theta0 = 0.3651, 0.01, 3e-3, 0.1
    pendulum = Pendulum(Rig(kind="torsion", stiffness=k), inertia, {"coulomb": {"Tc": torque}})
    t = np.linspace(0, 40, 8001)
    x, v = pendulum.motion(t, theta0)
    amp, sign = theta0, 1.0
    while abs(amp) > torque / k:
        amp = -(amp - sign * 2 * torque / k)
        sign = -sign
        if abs(amp) <= torque / k:
            break
    assert x[-1] == pytest.approx(amp, abs=1e-9)
    assert np.all(v[-100:] == 0.0)


@pytest.mark.parametrize("name", list(EFFECTS))
def test_every_effect_term_matches_its_basis(name):
    """The integrator's generated term and the vectorised basis must agree, for any new effect too."""
    for kind in ("torsion", "compound"):
        if kind not in EFFECTS[name].rigs:
            continue
        eff = EFFECTS[name](Rig(kind=kind, stiffness=1.0) if kind == "torsion" else Rig(kind=kind))
        if eff.role == "sensor":
            t = np.linspace(0, 1, 5)
            assert eff.sensor_basis(t, np.sin(t)).shape == (5, len(eff.parameters))
            continue
        rng = np.random.default_rng(0)
        th, om = rng.uniform(-1, 1, 50), rng.uniform(-2, 2, 50)
        params = rng.uniform(0.1, 1, len(eff.parameters))
        basis = eff.basis(th, om) @ params
        env = {"cos": math.cos, "sin": math.sin, "abs": abs, "exp": math.exp}
        env.update({f"p{j}": p for j, p in enumerate(params)})
        # an effect that remembers the last turning point is compared far from it, its memory
        # saturated in the direction of motion (its regressors are that limit)
        term = [eval(eff.term, dict(env, x=a, v=b, s=math.copysign(1.0, b), xr=a - 1e3 * math.copysign(1.0, b),
                                    zr=math.copysign(1.0, b))) for a, b in zip(th, om)]
        assert np.allclose(term, basis, rtol=1e-12, atol=1e-12)


def test_simulated_trace_is_quantised_held_and_uneven():
    rig = Rig(kind="torsion", stiffness=0.3651)
    trace = simulate_trace(Pendulum(rig, 0.01, {"viscous": {"c": 1e-4}}), theta0=0.2, duration=5, rate=100,
                           quantisation_bits=12, pre_trigger=0.5, jitter=0.2, seed=1)
    step = 2 * math.pi / 4096
    assert np.allclose(trace.angle / step, np.round(trace.angle / step))
    assert np.all(trace.angle[:50] == trace.angle[0])
    assert np.all(np.diff(trace.t) > 0) and np.std(np.diff(trace.t)) > 1e-4


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan")])
def test_pendulum_rejects_non_physical_inertia(bad):
    with pytest.raises(InvalidInput, match="inertia"):
        Pendulum(Rig(kind="torsion", stiffness=1.0), bad)


def test_noise_floor_is_exact_on_uneven_timestamps():
    from measurement.signal import noise_floor

    rng = np.random.default_rng(4)
    t = np.cumsum(rng.uniform(2e-3, 6e-3, 6000))  # an encoder polled as fast as the bus allows
    y = 0.3 * np.cos(5.4 * t) + rng.normal(0, 1e-4, t.size)
    assert noise_floor(y, t=t) == pytest.approx(1e-4, rel=0.05)
