"""Work computed once and shared (between preparation, fits and diagnostics) gives what computing it afresh gives."""

import numpy as np
import pytest

from measurement import Options, Pendulum, Rig, Trace, simulate_trace
from measurement.diagnostics import _fit_residual
from measurement.fit import fit_model
from measurement.identification.preparation import prepare
from measurement.model import Model
from measurement.noise import autocorrelation, lagged_products
from measurement.signal import deviation_table, loo_deviations, noise_floor, spike_candidates
from measurement.starting import smooth

RIG = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))


@pytest.fixture(scope="module")
def trace():
    truth = Pendulum(RIG, 0.0125, {"viscous": {"c": 1e-4}, "coulomb": {"Tc": 1.5e-4}})
    return simulate_trace(truth, theta0=0.25, duration=10, rate=200, noise_std=1e-4, quantisation_bits=17, seed=4)


def test_a_fits_residual_jacobian_and_swing_are_those_of_its_own_solution(trace):
    # the residual and Jacobian at the solution are reused from the solver's own evaluations: not stale ones
    prep = prepare(trace)
    model = Model.from_names(RIG, ("viscous", "coulomb"))
    fit = fit_model(model, prep.t, prep.y, prep.noise, swings=prep.swings)
    theta, omega = model.true_angle(fit.x, prep.t, fit.max_step)
    ts = prep.t - prep.t[0]
    assert np.array_equal(fit.residual, model.measured(fit.x, ts, theta) - prep.y)
    assert np.array_equal(fit.extra["theta"], theta) and np.array_equal(fit.extra["omega"], omega)
    fresh = fit_model(model, prep.t, prep.y, prep.noise, x0=fit.x, scales=fit.scales, max_step=fit.max_step,
                      max_nfev=1)  # one evaluation: the Jacobian at fit.x, computed afresh
    assert np.array_equal(fresh.jac, fit.jac)


def test_the_next_model_reuses_the_smoothing_only_of_the_same_samples(trace):
    prep = prepare(trace)
    base = fit_model(Model.from_names(RIG, ("viscous",)), prep.t, prep.y, prep.noise)
    same = fit_model(Model.from_names(RIG, ("viscous", "coulomb")), prep.t, prep.y, prep.noise, previous=base)
    assert same.extra["smoothed"] is base.extra["smoothed"]
    t, y = prep.t[5:], prep.y[5:]
    other = fit_model(Model.from_names(RIG, ("viscous", "coulomb")), t, y, prep.noise, previous=base)
    assert other.extra["smoothed"] is not base.extra["smoothed"] and other.extra["smoothed"].t is t
    fresh = smooth(prep.t, prep.y, prep.noise)
    for name in ("centre", "window", "dt"):
        assert getattr(fresh, name) == getattr(base.extra["smoothed"], name)
    assert np.array_equal(fresh.ys, base.extra["smoothed"].ys)


def test_the_noise_floors_and_the_glitch_screen_read_one_table_as_they_would_compute_it(trace):
    t, y = trace.t, trace.angle.copy()
    y[[100, 101, 900, 1995]] += [0.02, -0.015, 0.01, 0.03]  # two glitches side by side, one near the end
    table = deviation_table(y, t)
    idx, dev = loo_deviations(t, y, 3)
    assert np.array_equal(table[3][0], idx) and np.array_equal(table[3][1], dev)
    sigma = noise_floor(y, robust=True, t=t)
    assert noise_floor(y, robust=True, t=t, table=table) == sigma
    spikes = spike_candidates(y, sigma, t=t, table=table)
    assert {100, 900, 1995} <= set(spikes.tolist()) and np.array_equal(spikes, spike_candidates(y, sigma, t=t))
    assert np.array_equal(table[3][1], dev)  # the screen left the shared table alone
    assert noise_floor(y, exclude=spikes, t=t, table=table) == pytest.approx(1e-4, rel=0.1)


def test_lagged_products_by_dot_and_by_fft_agree_with_the_definition():
    r = np.random.default_rng(3).normal(size=700)
    r -= r.mean()
    for lags in (0, 5, 32, 100):
        direct = np.array([np.sum(r[: r.size - k] * r[k:]) for k in range(lags + 1)])
        assert np.allclose(lagged_products(r, lags), direct, rtol=1e-12, atol=1e-9)
    assert autocorrelation(r[:3], 10).size == 11  # more lags than samples: zeros beyond


def test_structure_regression_residual_is_the_least_squares_one_also_when_rank_deficient():
    rng = np.random.default_rng(5)
    X = rng.normal(size=(400, 6))
    b = X @ rng.normal(size=6) + rng.normal(size=400)
    ref = b - X @ np.linalg.lstsq(X, b, rcond=None)[0]
    assert np.allclose(_fit_residual(X, b), ref, rtol=0, atol=1e-12 * np.abs(b).max())
    Xd = np.column_stack([X, X[:, 0] + X[:, 1]])  # a column that repeats two others: the SVD path
    refd = b - Xd @ np.linalg.lstsq(Xd, b, rcond=None)[0]
    assert np.allclose(_fit_residual(Xd, b), refd, rtol=0, atol=1e-12 * np.abs(b).max())


def test_prepare_keeps_the_swings_of_its_window(trace):
    from measurement.signal import find_swings

    prep = prepare(trace, Options())
    sw = find_swings(prep.t, prep.y, hysteresis=3 * prep.noise)
    assert prep.swings is not None
    assert np.array_equal(prep.swings.crossings, sw.crossings) and prep.swings.centre == sw.centre
    keep = (trace.t < 6.0) | (trace.t > 9.5)  # half a second after a 3.5 s gap: the window ends at the gap
    cut = prepare(Trace(trace.t[keep], trace.angle[keep], source="gap"), Options())
    assert cut.gap_cut_at is not None and cut.t[-1] < 6.0
    sw_cut = find_swings(cut.t, cut.y, hysteresis=3 * cut.noise)
    assert cut.swings is not None and np.array_equal(cut.swings.crossings, sw_cut.crossings) and cut.swings.crossings[-1] < 6.0
