"""Whole-record fit of one model: starting values, least squares, noise model, uncertainties.

1. Starting values by equation error (``starting``), and the previous
   model's values overlaid on them.
2. Output error: nonlinear least squares of the simulated response against
   every sample (scipy ``least_squares``, trust-region reflective, bounds
   keep dissipation ≥ 0), optionally with a robust loss (soft-L1) so that a
   few wild samples cannot steer the fit. The Jacobian is a forward
   difference of the simulation for the dynamic parameters and exact for the
   offset and the sensor terms, which enter linearly.
3. The residual's noise model (``noise.fit_noise``, AR(p) with the order
   chosen by the data) gives the likelihood (BIC) and the covariance: the
   sandwich with the AR covariance, which reduces to s²·(JᵀJ)⁻¹ when the
   residual is white. The uncertainty stated (``with_score_floor``, once
   the models are chosen) takes ω_n's variance no lower than what the
   record's own residual says, one stretch of a few swings left out at a
   time (the linearised jackknife, ``score_variance``): noise that sits where the information lies
   (time-stamp jitter errs by θ'·δt, largest at the zero crossings that date
   the swing) or wanders for seconds, which no AR model of the residual sees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from .errors import IdentificationError
from .model import Model
from .noise import NoiseModel, fit_noise
from .signal import Swings
from .starting import Smoothed, initial_guess, smooth

#: equal stretches of the record, each left out in turn, whose moves of the estimate give its variance
#: whatever the noise is like (``score_variance``): enough for a variance good to some 35 %, few
#: enough that each spans a few swings, longer than the wander of a host's time stamps
SCORE_BLOCKS = 16
#: the largest correlation between neighbouring stretches' influences credited: σ at most 3× the batch means'
MAX_BLOCK_CORRELATION = 0.8

__all__ = ["ModelFit", "fit_model", "with_score_floor"]


@dataclass(frozen=True, eq=False)
class ModelFit:
    """Outcome of fitting one model to the fitted samples (t, y).

    residual: y_model − y (rad); effective: the residual as the loss sees it
    (equal to residual without a robust loss; wild samples shrunk with one);
    noise: the AR noise model of ``effective``; jac: the Jacobian (rad per
    parameter unit) at the solution.
    """

    model: Model
    x: np.ndarray
    cov: np.ndarray
    t: np.ndarray
    y: np.ndarray
    fitted: np.ndarray
    residual: np.ndarray
    rss: float
    success: bool
    message: str
    nfev: int
    max_step: float
    noise: NoiseModel
    effective: np.ndarray
    jac: np.ndarray
    scales: np.ndarray
    cov_method: str = "white"
    cov_inflation: float = 1.0
    at_bound: tuple[str, ...] = ()
    f_scale: float | None = None
    n_downweighted: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def names(self) -> tuple[str, ...]:
        return self.model.names

    @property
    def n(self) -> int:
        return int(self.y.size)

    @property
    def k(self) -> int:
        return int(self.x.size)

    @property
    def dof(self) -> int:
        return self.n - self.k

    @property
    def residual_rms(self) -> float:
        return float(math.sqrt(float(self.residual @ self.residual) / self.n))

    @property
    def log_likelihood_term(self) -> float:
        """n·log σ_e² (−2·log-likelihood up to a constant) under the AR noise model."""
        return float(self.n * math.log(max(self.noise.innovation_var, 1e-300)))

    @property
    def n_params(self) -> int:
        """Model parameters plus the noise model's AR coefficients."""
        return self.k + self.noise.order

    @property
    def aic(self) -> float:
        return self.log_likelihood_term + 2 * self.n_params

    @property
    def bic(self) -> float:
        return self.log_likelihood_term + self.n_params * math.log(self.n)

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.cov), 0.0, None))

    def value(self, name: str) -> float:
        """A scalar parameter by name: "omega_n", "offset", "theta0", "coulomb.Tc_per_J", ..."""
        return self.model.value(self.x, name)

    def stdev(self, name: str) -> float:
        return float(self.std[self.model.index(name)])

    def effect(self, name: str) -> list[float]:
        """An effect's fitted values (its ``parameters`` order)."""
        return self.model.values(self.x, name)


def start_candidates(model: Model, x: np.ndarray, previous: "ModelFit | None") -> list[np.ndarray]:
    """Starting vectors worth trying: the regression's, and the previous fit's
    values overlaid on it (all of them, or only the initial state and the
    sensor terms). Adding an effect can move ω_n a lot (a hardening spring
    lowers the small-amplitude frequency), so neither start always wins."""
    starts = [x]
    if previous is None:
        return starts
    lo_b, hi_b = model.bounds()
    full, state = x.copy(), x.copy()
    pm = previous.model
    for name in ("theta0", "omega0", "omega_n", "offset"):
        full[model.index(name)] = previous.value(name)
        if name != "omega_n":
            state[model.index(name)] = previous.value(name)
    for e in pm.effects:
        if e.name in model.layout:
            full[model.layout[e.name]] = previous.effect(e.name)
            if e.role == "sensor":
                state[model.layout[e.name]] = previous.effect(e.name)
    starts += [np.clip(full, lo_b, hi_b), np.clip(state, lo_b, hi_b)]
    refining = [(e, e.refines) for e in model.effects if e.refines is not None and e.refines in pm.layout]
    if refining:
        # start from the fit it refines: the same values, the new parameters at sizes worth trying
        theta = np.abs(previous.extra["theta"])
        amplitudes = (float(np.max(theta)), float(np.max(theta[-max(1, theta.size // 10):])))
        for e, refined in refining:
            for vals in e.refined_start(previous.effect(refined), amplitudes):
                x_ref = full.copy()
                x_ref[model.layout[e.name]] = vals
                starts.append(np.clip(x_ref, lo_b, hi_b))
    return starts


# -- least squares --------------------------------------------------------------------


def fit_model(model: Model, t: np.ndarray, y: np.ndarray, sigma: float, *,
              x0: np.ndarray | None = None, scales: np.ndarray | None = None,
              previous: ModelFit | None = None, max_step: float | None = None,
              max_nfev: int = 200, f_scale: float | None = None, swings: Swings | None = None) -> ModelFit:
    """Fit ``model`` to every sample (t in s, y the sensor's reading: rad, or rad/s on a rate sensor);
    sigma: noise floor, in y's unit.

    f_scale: with a value (rad), a robust soft-L1 loss: residuals well beyond
    f_scale count in proportion to their size rather than its square.
    swings: ``find_swings(t, y, hysteresis=3 * sigma)`` when the caller has it.
    The starting values' model-independent part (``smooth``) is taken from
    ``previous`` when that was fitted to the very same samples.
    """
    starts = None
    smoothed = previous.extra.get("smoothed") if previous is not None else None
    if x0 is None or scales is None:
        if smoothed is None or not smoothed.holds(t, y, sigma):
            smoothed = smooth(t, y, sigma, swings)
        x_reg, scales = initial_guess(model, t, y, sigma, smoothed)
        starts = start_candidates(model, x_reg, previous)
    else:
        starts = [x0]
    if max_step is None:
        max_step = model.max_step(starts[0], model.amplitude(starts[0], y))
    sim = _Simulation(model, t, y, max_step, 1e-7 * scales[:model.n_dynamic])
    # A model that contains the previous one fits the same samples at least as well; ending
    # worse, the solver went down another basin from the cheapest start (over a long record
    # a start near a poor fit can slip a cycle): the other starts are tried, the best kept.
    beaten = None
    if previous is not None and previous.f_scale == f_scale and previous.t.size == t.size and np.array_equal(previous.t, t):
        beaten = 0.5 * previous.rss * (1.0 + 1e-6)
    sol = _solve(sim, starts, scales, max_nfev, f_scale, beaten)
    return _outcome(sim, sol, scales, f_scale, smoothed)


class _Simulation:
    """The model's response to one record, as least squares asks for it: the residual and its Jacobian.

    The last few evaluations are kept by x: scipy evaluates the residual and the Jacobian at the
    solution before it returns, the starting-value choice evaluates the start least_squares
    begins with, and the fit's outputs need both at the solution again; each is simulated once.
    Copies go out: a robust loss scales scipy's arrays in place.
    """

    def __init__(self, model: Model, t: np.ndarray, y: np.ndarray, max_step: float, steps: np.ndarray):
        self.model, self.t, self.y, self.max_step, self.steps = model, t, y, max_step, steps
        self.ts = t - t[0]
        self.nfev = 0
        self._evaluated: dict[bytes, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}  # x → (measured, θ, θ')
        self._jac: dict[bytes, np.ndarray] = {}

    def simulate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self.nfev += 1
        return self.model.true_angle(x, self.t, self.max_step)

    def evaluate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(the sensor's reading, θ, θ') of the model at x."""
        key = x.tobytes()
        hit = self._evaluated.get(key)
        if hit is None:
            theta, omega = self.simulate(x)
            hit = (self.model.measured(x, self.ts, theta, omega), theta, omega)
            if len(self._evaluated) >= 4:
                del self._evaluated[next(iter(self._evaluated))]
            self._evaluated[key] = hit
        return hit

    def fun(self, x: np.ndarray) -> np.ndarray:
        return self.evaluate(x)[0] - self.y

    def jac(self, x: np.ndarray) -> np.ndarray:
        """Forward differences for the dynamic parameters, exact columns for the offset and the sensor terms."""
        key = x.tobytes()
        if key in self._jac:
            return self._jac[key].copy()
        model, nd = self.model, self.model.n_dynamic
        _, hi = model.bounds()
        base, theta, omega = self.evaluate(x)
        J = np.empty((self.t.size, x.size))
        for j in range(nd):
            xp = x.copy()
            h = self.steps[j]
            # step inwards at a bound so the perturbed model stays physical
            if xp[j] + h > hi[j]:
                h = -h
            xp[j] += h
            J[:, j] = (model.measured(xp, self.ts, *self.simulate(xp)) - base) / h
        J[:, nd:] = model.sensor_columns(self.ts, model.reading(theta, omega))
        self._jac.clear()
        self._jac[key] = J.copy()
        return J


def _solve(sim: _Simulation, starts: list[np.ndarray], scales: np.ndarray, max_nfev: int,
           f_scale: float | None, beaten: float | None) -> OptimizeResult:
    """Least squares from the cheapest start, then the others while the cost stays above ``beaten``."""
    order = [0]
    if len(starts) > 1:
        costs = [float(np.sum(sim.fun(xs) ** 2)) for xs in starts]
        order = [int(i) for i in np.argsort(costs)]
    lo, hi = sim.model.bounds()
    loss = "linear" if f_scale is None else "soft_l1"
    sol = None
    failed: Exception | None = None
    for i in order:
        try:
            trial = least_squares(sim.fun, starts[i], jac=sim.jac, bounds=(lo, hi), x_scale=scales, method="trf",
                                  ftol=1e-12, xtol=1e-12, gtol=1e-10, max_nfev=max_nfev,
                                  loss=loss, f_scale=1.0 if f_scale is None else f_scale)
        except (ValueError, FloatingPointError, OverflowError, ZeroDivisionError, np.linalg.LinAlgError) as exc:
            failed = exc
            continue
        if sol is None or trial.cost < sol.cost:
            sol = trial
        if beaten is None or sol.cost <= beaten:
            break
    if sol is None:
        raise IdentificationError(f"least squares failed for model {sim.model.effect_names}: {failed}") from failed
    return sol


def _outcome(sim: _Simulation, sol: OptimizeResult, scales: np.ndarray, f_scale: float | None,
             smoothed: Smoothed | None) -> ModelFit:
    """The ``ModelFit`` at the solution: residual, noise model, covariance, parameters at a bound."""
    model, x = sim.model, sol.x
    _, theta, omega = sim.evaluate(x)
    residual = sim.fun(x)
    if not np.all(np.isfinite(residual)):
        raise IdentificationError(f"model {model.effect_names} diverged (non-finite simulation)")
    J = sim.jac(x)
    effective, weight = robust_residual(residual, f_scale)
    noise = fit_noise(effective)
    cov, method, inflation = covariance(J * np.sqrt(weight)[:, None], effective, scales, noise)
    lo, hi = model.bounds()
    tol = 1e-9 * scales
    at_bound = tuple(n for n, v, l, u, s in zip(model.names, x, lo, hi, tol)
                     if (np.isfinite(l) and v - l <= s) or (np.isfinite(u) and u - v <= s))
    return ModelFit(
        model=model, x=x, cov=cov, t=sim.t, y=sim.y, fitted=sim.y + residual, residual=residual,
        rss=float(effective @ effective), success=bool(sol.success), message=str(sol.message), nfev=sim.nfev,
        max_step=sim.max_step, noise=noise, effective=effective, jac=J, scales=scales,
        cov_method=method, cov_inflation=inflation, at_bound=at_bound, f_scale=f_scale,
        n_downweighted=int(np.sum(weight < 0.5)),
        # the true swing at x (rad, rad/s); what the starting values read from (t, y), for the next model
        extra={"theta": theta, "omega": omega, "smoothed": smoothed},
    )


def with_score_floor(fit: ModelFit, names: Sequence[str] = ("omega_n",)) -> ModelFit:
    """``fit`` with no variance of ``names`` below what its record's own residual says (``score_variance``).

    For the uncertainty stated, once the models are chosen: the choices weigh models by the noise
    model's σ, which a record's structure left unmodelled would otherwise inflate and so steer.
    ω_n alone by default: the laws of an object are judged across its releases by their
    parameters' σ, which stay as the noise model has them.
    """
    effective, weight = robust_residual(fit.residual, fit.f_scale)
    cov, method, inflation = covariance(fit.jac * np.sqrt(weight)[:, None], effective, fit.scales, fit.noise,
                                        t=fit.t, floored=[fit.model.index(n) for n in names])
    return replace(fit, cov=cov, cov_method=method, cov_inflation=inflation)


def swing_amplitude(fit: ModelFit) -> float:
    """The fitted swing's largest angle, rad: as the sensor reads it about its zero (an angle sensor's
    terms included), or on a rate sensor, whose reading is a rate, the true swing's."""
    if fit.model.measures == "rate":
        return float(np.max(np.abs(fit.extra["theta"])))
    return float(np.max(np.abs(fit.fitted - fit.value("offset"))))


def robust_residual(residual: np.ndarray, f_scale: float | None) -> tuple[np.ndarray, np.ndarray]:
    """(effective residual, weight) of the soft-L1 loss ρ(z) = 2(√(1+z) − 1), z = (r/f)².

    The effective residual sign(r)·f·√ρ has the loss as its sum of squares (so
    the noise model and BIC see what the fit minimised); the weight ρ'(z) =
    1/√(1+z) is the share of a sample's information the fit used.
    """
    if f_scale is None:
        return residual, np.ones_like(residual)
    z = (residual / f_scale) ** 2
    rho = 2.0 * (np.sqrt(1.0 + z) - 1.0)
    return np.sign(residual) * f_scale * np.sqrt(rho), 1.0 / np.sqrt(1.0 + z)


def _inverse_gram(Js: np.ndarray) -> np.ndarray:
    """(JᵀJ)⁻¹ of a scaled Jacobian (the pseudo-inverse when it is singular)."""
    JtJ = Js.T @ Js
    try:
        return np.linalg.inv(JtJ)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(JtJ)


def _coloured_gram(Js: np.ndarray, blocks: Sequence[tuple[slice, NoiseModel, float]]) -> np.ndarray:
    """JᵀΣJ for rows in independent blocks, each with its own AR noise model and the parameters
    charged to it (its degrees of freedom): Σ_b σ_e²·‖A_b⁻ᵀJ_b‖²·n_b/(n_b − k_b)."""
    middle = np.zeros((Js.shape[1], Js.shape[1]))
    for rows, noise, k in blocks:
        G = noise.colour_t(Js[rows])
        n = G.shape[0]
        middle += noise.innovation_var * (G.T @ G) * (n / max(n - k, 1))
    return middle


def block_covariance(J: np.ndarray, scales: np.ndarray,
                     blocks: Sequence[tuple[slice, NoiseModel, float]]) -> np.ndarray:
    """Parameter covariance of a least-squares estimate over several independent stretches of samples
    (rows of J), each with its own AR noise model: the sandwich of ``covariance`` block by block."""
    Js = J * scales
    inv = _inverse_gram(Js)
    return (inv @ _coloured_gram(Js, blocks) @ inv) * np.outer(scales, scales)


def covariance(J: np.ndarray, residual: np.ndarray, scales: np.ndarray, noise: NoiseModel | None = None,
               t: np.ndarray | None = None, floored: Sequence[int] = ()) -> tuple[np.ndarray, str, float]:
    """Parameter covariance of the least-squares estimate under the AR noise model.

    cov = (JᵀJ)⁻¹·JᵀΣJ·(JᵀJ)⁻¹ with Σ = σ_e²·A⁻¹A⁻ᵀ (``noise``); for white
    noise this is s²·(JᵀJ)⁻¹. t (s): the samples' times; with them the
    variance of each parameter in ``floored`` (indices) is taken no lower
    than its ``score_variance`` (the noise where the information lies). Returns (cov, method, inflation): method
    "white" or "ar(p)", inflation the largest ratio of a σ to its white-noise value.
    """
    n, k = J.shape
    Js = J * scales  # scaled for conditioning
    inv = _inverse_gram(Js)
    if noise is None:
        noise = fit_noise(residual)
    s2 = float(residual @ residual) / max(n - k, 1)
    white = inv * s2
    cov, method = white, "white"
    if noise.order > 0:
        cov, method = inv @ _coloured_gram(Js, [(slice(None), noise, k)]) @ inv, f"ar({noise.order})"
    floor = None if t is None or not len(floored) else score_variance(Js, residual, t)
    if floor is not None:
        q = np.ones(k)
        q[floored] = np.sqrt(np.maximum(floor[floored] / np.maximum(np.diag(cov)[floored], 1e-300), 1.0))
        cov = cov * np.outer(q, q)
    d_white, d_cov = np.diag(white), np.diag(cov)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratios = np.sqrt(np.where(d_white > 0, d_cov / d_white, 1.0))
    return cov * np.outer(scales, scales), method, float(np.max(ratios))


def score_variance(Js: np.ndarray, residual: np.ndarray, t: np.ndarray, blocks: int = SCORE_BLOCKS) -> np.ndarray | None:
    """Each parameter's variance (in Js's scaling) read from the record's own residual, by leaving out
    one of ``blocks`` equal stretches of time at a time (the linearised jackknife).

    Leaving out stretch b moves the estimate by ψ_b = (JᵀJ − J_bᵀJ_b)⁻¹·J_bᵀ·r_b. Over stretches
    of a few swings these moves are nearly independent whatever the noise is like where the
    information lies: a time stamp off by δt errs by θ'·δt, largest at the zero crossings that
    date the swing, and the wander of a host's stamps lasts seconds, out of reach of an AR model
    of the residual. The variance is (B − 1)/B·Σ ψ_b²; the correlation left between neighbouring
    stretches (a wander as long as a stretch) counts as an AR(1)'s long-run variance,
    (1 + ρ)/(1 − ρ), ρ at most ``MAX_BLOCK_CORRELATION``. None when the record is too short.
    """
    n, k = Js.shape
    if n < blocks * max(2 * k, 8):
        return None
    edges = np.unique(np.searchsorted(t, t[0] + (t[-1] - t[0]) * np.arange(blocks) / blocks))
    if edges.size < blocks // 2:
        return None
    gram = Js.T @ Js
    bounds = np.append(edges, n)
    psi = np.empty((edges.size, k))
    for i, (lo, hi) in enumerate(zip(bounds[:-1], bounds[1:])):
        Jb = Js[lo:hi]
        # a stretch that alone determines a parameter leaves the rest singular: the least-norm move
        psi[i] = np.linalg.lstsq(gram - Jb.T @ Jb, Jb.T @ residual[lo:hi], rcond=None)[0]
    b = psi.shape[0]
    power = np.sum(psi**2, axis=0)
    rho = np.clip(np.sum(psi[1:] * psi[:-1], axis=0) / np.maximum(power, 1e-300), 0.0, MAX_BLOCK_CORRELATION)
    return power * (b - 1) / b * (1.0 + rho) / (1.0 - rho)
