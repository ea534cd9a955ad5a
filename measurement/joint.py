"""Several releases of one object, one identification.

Each release is identified on its own first (its window, noise, glitches,
discovery and model form). The releases are then fitted jointly: the
physics is shared (ω_n and the damping and stiffness laws: the union of the
dynamic effects any release needed), the nuisance is per release (initial
state, sensor zero, drift and other sensor terms). Before that, a restoring law a
release added is weighed across the releases (``object_laws``): one not of
the object (its value changes sign or size between releases) is withdrawn
from every release that kept it. Releases at different
amplitudes are how amplitude-dependent physics is told from a constant ω_n:
the shared laws are chosen by the joint BIC among the union, each release's
own set, and the same with a restoring law in place of what mimics it
(``_candidate_sets``), provided the choice holds across every release's
record as well as its own model did (``_not_held``).

The releases are then tested against the joint value: χ² of each release's
own ω_n (with its combined uncertainty) about the joint one, the largest
normalised deviation and the release it points to, and the largest
normalised difference between two releases. When they scatter more than
their uncertainties allow, the joint σ is scaled by the Birge ratio
√(χ²/dof) (R. T. Birge, "The calculation of errors by the method of least
squares", Phys. Rev. 40, 1932) and the result is flagged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import numpy as np
from scipy.optimize import least_squares
from scipy.special import gammaincc

from . import flags as F
from .consistency import bic_weights, check_segments
from .effects import EFFECTS, resolve_effects, unweighed_law
from .errors import IdentificationError, InvalidInput
from .fit import ModelFit, block_covariance, fit_model
from .identification.measurand import read_at
from .identification.options import Options
from .identification.pipeline import identify
from .identification.quantities import budgets, effect_quantities, inertia
from .identification.rivals import fallback
from .identification.threads import one_blas_thread
from .model import STATE_PARAMS, Model
from .noise import fit_noise
from .object_laws import laws_of_the_object
from .result import RECORD, RELEASES, IdentificationResult, Quantity, ReadAt, _jsonable, _num, quantities_from_dict
from .rig import Rig
from .trace import Trace
from .uncertainty import Budget

#: distance (in combined σ) beyond which the joint fit's ω_n and the releases' weighted value disagree
FIT_APART_Z = 2.0

#: p-value of the releases' χ² below which they are inconsistent (flag releases_disagree)
CONSISTENT_P = 0.01

#: distance (in combined u) beyond which two releases' own readings of ω_n, each as its own identification
#: reports it, disagree (flag releases_disagree): what a user comparing two reports of one object sees
OWN_PAIR_Z = 2.0


@dataclass(frozen=True, eq=False)
class JointResult:
    """The joint identification of several releases of one object. SI units; *_std are 1σ.

    omega_n: the releases' ω_n (each fitted alone with the shared effects)
    weighted by their combined uncertainties; omega_n_std: its σ;
    omega_n_u: σ scaled by the Birge ratio when the releases scatter beyond
    their uncertainties, and never below the releases' common model-form and
    calibration terms. The damping laws are the joint fit's (all samples,
    shared physics; its own ω_n is consistency.joint_fit). releases: each
    release identified alone.
    consistency: chi2, dof, p, the largest normalised deviation from the
    joint value and its release, the largest normalised pairwise difference.
    """

    rig_kind: str
    effects: tuple[str, ...]
    omega_n: float
    omega_n_std: float
    omega_n_u: float
    J: float | None
    J_std: float | None
    J_u: float | None
    damping: dict[str, dict[str, Quantity]]
    stiffness: dict[str, dict[str, Quantity]]
    residual_rms: float
    consistency: dict[str, Any]
    flags: tuple[str, ...]
    releases: tuple[IdentificationResult, ...]
    #: measurand → its GUM budget (``measurement.uncertainty``) on the joint ω_n ± omega_n_u; the releases'
    #: scatter (when it sets omega_n_u) counts with its n − 1 degrees of freedom
    uncertainty_budget: dict[str, Budget] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        declared = self.releases[0].declared_effects
        return {
            "joint": True, "rig_kind": self.rig_kind,
            "J": _num(self.J), "J_std": _num(self.J_std), "J_u": _num(self.J_u),
            "J_U": _num(self.uncertainty_budget["J"].U) if "J" in self.uncertainty_budget else None,
            "uncertainty_budget": _jsonable({k: b.to_dict() for k, b in self.uncertainty_budget.items()}),
            "omega_n": _num(self.omega_n), "omega_n_std": _num(self.omega_n_std), "omega_n_u": _num(self.omega_n_u),
            "declared_effects": list(declared), "effects": list(self.effects),
            "added_effects": [e for e in self.effects if e not in declared],
            "damping": {e: {k: q.to_dict() for k, q in ps.items()} for e, ps in self.damping.items()},
            "stiffness": {e: {k: q.to_dict() for k, q in ps.items()} for e, ps in self.stiffness.items()},
            "residual_rms": _num(self.residual_rms),
            "baseline": {"effects": list(declared), "omega_n": [_num(r.baseline.omega_n) for r in self.releases]},
            "consistency": _jsonable(self.consistency),
            "flags": list(self.flags),
            "warnings": list(F.warnings(self.flags)),
            "releases": [r.to_dict() for r in self.releases],
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> JointResult:
        """Read back ``to_dict`` (each release by ``IdentificationResult.from_dict``; the keys derived from the
        releases and the budget, declared_effects, added_effects, baseline and J_U, are computed again)."""
        number = {k: math.nan if d[k] is None else d[k] for k in ("omega_n", "omega_n_std", "omega_n_u", "residual_rms")}
        return cls(
            rig_kind=d["rig_kind"], effects=tuple(d["effects"]), J=d["J"], J_std=d["J_std"], J_u=d["J_u"], **number,
            damping=quantities_from_dict(d["damping"]), stiffness=quantities_from_dict(d["stiffness"]),
            consistency=dict(d["consistency"]), flags=tuple(d["flags"]),
            releases=tuple(IdentificationResult.from_dict(r) for r in d["releases"]),
            uncertainty_budget={k: Budget.from_dict(b) for k, b in d["uncertainty_budget"].items()},
        )

    def to_json(self) -> str:
        import json
        return json.dumps(self.to_dict(), ensure_ascii=False, allow_nan=False)


def _own_pair(results: Sequence[IdentificationResult]) -> tuple[float, int, int]:
    """The two releases whose own readings of ω_n (each with its stated u) are furthest apart: (|Δω_n|/u, i, j)."""
    def u(r: IdentificationResult) -> float:
        return r.omega_n_u if r.omega_n_u is not None else r.omega_n_std

    return max(((abs(results[a].omega_n - results[b].omega_n) / math.hypot(u(results[a]), u(results[b])), a, b)
                for a in range(len(results)) for b in range(a + 1, len(results))), key=lambda v: v[0])


def _dynamic(names: Sequence[str], rig: Rig) -> tuple[str, ...]:
    """The dynamic effects among ``names`` (a refinement replacing what it refines), in library order."""
    kept = {n for n in names if EFFECTS[n].role != "sensor"}
    kept -= {EFFECTS[n].refines for n in kept}
    return tuple(e.name for e in resolve_effects(kept, rig))


def _shared_effects(results: Sequence[IdentificationResult], rig: Rig) -> tuple[str, ...]:
    """The dynamic effects any release needed, in library order."""
    return _dynamic([n for r in results for n in r.effects], rig)


def identify_releases(traces: Sequence[Trace], rig: Rig, options: Options | None = None) -> JointResult:
    """Identify several releases of one object on ``rig`` jointly (see the module doc); options: ``Options()``."""
    # each release enters with its discovered model: the joint fit weighs the laws the releases found, and a
    # release's headline read from its declared model (identification.focus) is for that release alone
    options = replace(Options() if options is None else options, focused=False)
    if len(traces) < 2:
        raise InvalidInput(f"a joint identification needs at least 2 releases, got {len(traces)}")
    results, options = one_amplitude([identify(tr, rig, options) for tr in traces], traces, rig, options)
    results, _ = laws_of_the_object(results, traces, rig, options)
    return _joint(results, rig, options.bic_margin)


def one_amplitude(results: list[IdentificationResult], traces: Sequence[Trace], rig: Rig,
                  options: Options) -> tuple[list[IdentificationResult], Options]:
    """The releases read at one swing amplitude, and the options that read there (``identification.measurand``).

    One object, one measurand: where each release read ω at its own amplitude (a torsion rig whose calibration
    states none), a fitted amplitude law reads it at the releases' mean amplitude instead, so that the joint
    value and the releases' scatter compare one quantity; a release without such a law reads the same ω at
    every amplitude and is only relabelled.
    """
    if any(r.omega_n_read_at.basis != RECORD for r in results):
        return results, options
    amplitude = float(np.mean([r.omega_n_read_at.amplitude for r in results]))
    options = replace(options, reference_amplitude=amplitude, reference_basis=RELEASES)
    read = ReadAt(amplitude, RELEASES)
    return [identify(tr, rig, options) if r.stiffness else replace(r, omega_n_read_at=read)
            for r, tr in zip(results, traces)], options


def _joint(results: list[IdentificationResult], rig: Rig, margin: float = Options().bic_margin) -> JointResult:
    # tall, thin matrices, as in ``identify``: BLAS threads would only contend
    with one_blas_thread():
        return _fit_jointly(results, rig, margin)


@dataclass(frozen=True, eq=False)
class _SharedModelFit:
    """One joint fit of the releases with a shared set of dynamic effects.

    dropped: sensor effects of the releases' own models left out (a law stands for them);
    fits: each release alone with the shared model (the start, and its reading of ω_n);
    z, cov: the joint parameters (ω_n, the shared laws, then each release's own) and covariance;
    bic: the joint BIC, each release's residual under its own AR noise model, rad.
    """

    shared: tuple[str, ...]
    dropped: frozenset[str]
    models: list[Model]
    fits: list[ModelFit]
    z: np.ndarray
    cov: np.ndarray
    residuals: list[np.ndarray]
    blocks: list[tuple[int, int]]
    bic: float

    @property
    def omega_n(self) -> float:
        return float(self.z[0])

    @property
    def omega_n_std(self) -> float:
        return float(math.sqrt(max(self.cov[0, 0], 0.0)))

    def release_x(self, i: int) -> np.ndarray:
        """Release i's parameter vector in its own model's order."""
        return _release_x(self.models[i], self.blocks[i], self.z)

    def laws(self) -> _SharedFit:
        """The shared laws as a fit of the first release's model (the same effects for all)."""
        x0 = self.release_x(0)
        m0 = self.models[0]
        idx = list(range(m0.n_dynamic - len(STATE_PARAMS) + 1))
        cov0 = np.zeros((m0.size, m0.size))
        pos = [2] + list(range(3, m0.n_dynamic))
        cov0[np.ix_(pos, pos)] = self.cov[np.ix_(idx, idx)]
        return _SharedFit(m0, x0, cov0)

    def omega_at(self, amplitude: float) -> tuple[float, float]:
        """(the joint fit's ω at the swing ``amplitude`` (rad; 0: its ω_n), its 1σ), rad/s (``measurand``)."""
        return read_at(self.laws(), amplitude)


def _release_x(model: Model, block: tuple[int, int], z: np.ndarray) -> np.ndarray:
    """A release's parameters from the joint vector z: the shared ω_n and laws, then its own (``block``)."""
    a, b = block
    x = np.empty(model.size)
    x[0], x[1] = z[a], z[a + 1]
    x[2:model.n_dynamic] = z[:model.n_dynamic - len(STATE_PARAMS) + 1]
    x[model.n_dynamic:] = z[a + 2:b]
    return x


def _own_fits(results: Sequence[IdentificationResult], rig: Rig, shared: tuple[str, ...],
              drop: frozenset[str]) -> tuple[list[Model], list[ModelFit]]:
    """Each release's model (the shared dynamic effects, its own sensor terms but those in ``drop``) and its fit
    alone with it: the start of the joint fit."""
    models: list[Model] = []
    fits: list[ModelFit] = []
    for r in results:
        sensor = tuple(n for n in r.effects if EFFECTS[n].role == "sensor" and n not in drop)
        # each release's own sensor: an angle, or a gyro's rate
        model = Model.from_names(replace(rig, measures=r.measures), shared + sensor)
        fits.append(fit_model(model, r.arrays["t"], r.arrays["angle"], r.noise_floor))
        models.append(model)
    return models, fits


@dataclass(frozen=True, eq=False)
class _Start:
    """The joint parameter vector's start z0 (ω_n, the shared laws, then each release's own: ``blocks``), its
    bounds and scales; n_shared: how many lead it."""

    z0: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    scales: np.ndarray
    blocks: list[tuple[int, int]]
    n_shared: int


def _start(models: list[Model], fits: list[ModelFit]) -> _Start:
    dyn = list(models[0].names[len(STATE_PARAMS):models[0].n_dynamic])
    # start: ω_n and the laws averaged over the releases, each by its information
    var_w = np.array([max(f.stdev("omega_n"), 1e-12) ** 2 for f in fits])
    start: list[float] = [float(np.sum([f.value("omega_n") for f in fits] / var_w) / np.sum(1 / var_w))]
    start += [float(np.median(np.array([f.value(name) for f in fits]))) for name in dyn]
    blocks: list[tuple[int, int]] = []  # each release's own parameters in z
    for m, f in zip(models, fits):
        first = len(start)
        start += [f.value("theta0"), f.value("omega0")] + list(f.x[m.n_dynamic:])
        blocks.append((first, len(start)))
    lo_m, hi_m = models[0].bounds()
    lo: list[float] = [0.0] + list(lo_m[len(STATE_PARAMS):models[0].n_dynamic])
    hi: list[float] = [np.inf] + list(hi_m[len(STATE_PARAMS):models[0].n_dynamic])
    for m in models:
        lo_r, hi_r = m.bounds()
        lo += [-np.inf, -np.inf] + list(lo_r[m.n_dynamic:])
        hi += [np.inf, np.inf] + list(hi_r[m.n_dynamic:])
    scale_list = [fits[0].scales[2]] + list(np.median([f.scales[3:m.n_dynamic] for f, m in zip(fits, models)], axis=0)) \
        if dyn else [fits[0].scales[2]]
    for m, f in zip(models, fits):
        scale_list += [f.scales[0], f.scales[1]] + list(f.scales[m.n_dynamic:])
    lo_all, hi_all = np.asarray(lo), np.asarray(hi)
    return _Start(np.clip(np.asarray(start), lo_all, hi_all), lo_all, hi_all, np.asarray(scale_list), blocks,
                  1 + len(dyn))


def _solve_jointly(models: list[Model], fits: list[ModelFit], st: _Start, weights: np.ndarray) -> Any:
    """scipy's least squares over every release's samples, the Jacobian by forward differences of the
    releases each parameter moves (all for the shared ones, its own for the others)."""
    def release_residual(z: np.ndarray, i: int) -> np.ndarray:
        x = _release_x(models[i], st.blocks[i], z)
        t = fits[i].t
        th, om = models[i].true_angle(x, t, fits[i].max_step)
        return (models[i].measured(x, t - t[0], th, om) - fits[i].y) * weights[i]

    def fun(z: np.ndarray) -> np.ndarray:
        return np.concatenate([release_residual(z, i) for i in range(len(models))])

    offsets = np.concatenate([[0], np.cumsum([f.n for f in fits])])
    owners = [list(range(len(models)))] * st.n_shared + [[i] for i, (a, b) in enumerate(st.blocks) for _ in range(a, b)]

    def jac(z: np.ndarray) -> np.ndarray:
        base = [release_residual(z, i) for i in range(len(models))]
        J = np.zeros((offsets[-1], z.size))
        for j in range(z.size):
            h = 1e-7 * st.scales[j]
            zp = z.copy()
            zp[j] += h if zp[j] + h <= st.hi[j] else -h
            step = zp[j] - z[j]
            for i in owners[j]:
                J[offsets[i]:offsets[i + 1], j] = (release_residual(zp, i) - base[i]) / step
        return J

    try:
        return least_squares(fun, st.z0, jac=jac, bounds=(st.lo, st.hi), x_scale=st.scales, method="trf",
                             ftol=1e-10, xtol=1e-10, gtol=1e-10, max_nfev=60)
    except (ValueError, FloatingPointError, OverflowError, ZeroDivisionError) as exc:
        raise IdentificationError(f"the joint fit failed: {exc}") from exc


def _fit_shared(results: Sequence[IdentificationResult], rig: Rig, shared: tuple[str, ...],
                drop: frozenset[str] = frozenset()) -> _SharedModelFit:
    """The releases fitted jointly with the dynamic effects ``shared`` and each release's own sensor
    terms but those in ``drop``."""
    models, fits = _own_fits(results, rig, shared, drop)
    st = _start(models, fits)
    weights = np.array([1.0 / max(f.residual_rms, 1e-12) for f in fits])
    sol = _solve_jointly(models, fits, st, weights)
    z, r = sol.x, sol.fun
    # covariance: the sandwich with each release's own AR noise model (its residual's colour)
    offsets = np.concatenate([[0], np.cumsum([f.n for f in fits])])
    parts = [slice(offsets[i], offsets[i + 1]) for i in range(len(models))]
    noises = [fit_noise(r[sl]) for sl in parts]
    cov = block_covariance(sol.jac, st.scales, [(sl, nm, z.size / len(models)) for sl, nm in zip(parts, noises)])
    # the joint BIC: each release's residual under its own AR noise model (in rad², the weight taken
    # out of its innovation variance), as ModelFit.bic
    residuals = [r[sl] / weights[i] for i, sl in enumerate(parts)]
    n_all = int(offsets[-1])
    bic = float(sum(res.size * math.log(max(nm.innovation_var / w**2, 1e-300))
                    for res, nm, w in zip(residuals, noises, weights))
                + (z.size + sum(nm.order for nm in noises)) * math.log(n_all))
    return _SharedModelFit(shared, drop, models, fits, z, cov, residuals, st.blocks, bic)


#: most shared models fitted jointly (each costs about one identification of every release)
MAX_SHARED_MODELS = 8


def _candidate_sets(results: Sequence[IdentificationResult], rig: Rig) -> list[tuple[tuple[str, ...], frozenset[str]]]:
    """The shared dynamic effects the releases are fitted with, and the sensor effects left out of each
    release's own; the union first (``_shared_effects``), with every release's sensor terms.

    The others are what a release's own identification chose alone. Where
    effects mimic a restoring law the rig does not offer (Dahl's pre-sliding
    spring, a sensor's fitted scale: ``Effect.mimics``), each of these, and
    the union with each whole rival model a release could not rule out (an
    effect withdrawn because its ω_n did not hold across that record: the
    law the model lacked may be why), is fitted again with the law in their
    place: across releases at different amplitudes the data can tell them
    apart where one record could not. A withdrawn effect comes back only
    with the law: alone, its record already showed that it does not hold.
    """
    union = _shared_effects(results, rig)
    rivals = [list(c.effects) for r in results for c in r.model_form.competitors if c.effects]
    bases = list(dict.fromkeys([union] + [_dynamic(r.effects, rig) for r in results]))
    sets: list[tuple[tuple[str, ...], frozenset[str]]] = [(b, frozenset()) for b in bases]
    bases = list(dict.fromkeys(bases + [_dynamic(list(union) + e, rig) for e in rivals]))
    used = list(dict.fromkeys([n for b in bases for n in b] + [n for r in results for n in r.effects]
                              + [n for e in rivals for n in e]))
    for law in dict.fromkeys(m for n in used if (m := unweighed_law(EFFECTS[n], rig.kind)) is not None):
        drop = frozenset(n for n in used if EFFECTS[n].mimics == law and EFFECTS[n].role == "sensor")
        for base in bases:
            if law in base:
                continue
            keep, _ = fallback(base, [n for n in base if EFFECTS[n].mimics == law], ())
            key = (_dynamic(keep + [law], rig), drop)
            if key not in sets:
                sets.append(key)
    return sets[:MAX_SHARED_MODELS]


def _not_held(chosen: _SharedModelFit, results: Sequence[IdentificationResult]) -> list[str]:
    """The releases in which the shared model's halves disagree more than their own model's did."""
    out = []
    for f, r in zip(chosen.fits, results):
        seg = check_segments(f, r.noise_floor)
        segments = r.model_form.segments
        # halves of zero σ (z not finite) say nothing of their own model
        own = segments.z if segments is not None and math.isfinite(segments.z) else None
        if seg is not None and seg.disagree and (own is None or seg.z > own):
            out.append(r.source)
    return out


@dataclass(frozen=True, eq=False)
class _Choice:
    """The shared model kept among the candidates the joint BIC weighed: the one of least BIC unless its laws do
    not hold across releases (``not_held``: then the union); u_models: the spread of the candidates within the
    margin's joint ω_n about the kept one's, rad/s; table: every candidate, for the report."""

    chosen: _SharedModelFit
    not_held: list[str]
    u_models: float
    table: list[dict[str, Any]]


def read_amplitude(results: Sequence[IdentificationResult]) -> float:
    """The swing amplitude (rad) the joint fit's ω is read at: the releases' own (``IdentificationResult.omega_n_read_at``)
    averaged; 0 (the small-swing limit) where they read ω_n there."""
    return float(np.mean([r.omega_n_read_at.amplitude for r in results]))


def _choose(results: list[IdentificationResult], rig: Rig, margin: float) -> _Choice:
    # every candidate set of shared effects fitted jointly; the joint BIC chooses, and the sets within
    # ``margin`` of it are rivals whose joint ω_n enters u by their BIC weight
    candidates: list[_SharedModelFit] = []
    for shared, drop in _candidate_sets(results, rig):
        try:
            candidates.append(_fit_shared(results, rig, shared, drop))
        except IdentificationError:
            if not candidates:  # the union must fit: it is the model every release's physics is in
                raise
    best = min(candidates, key=lambda c: c.bic)
    # BIC alone can prefer a law that does not hold (``identification.rivals.hold_across``): a shared model
    # other than the union is kept only if, in each release, it holds across the record as well as
    # that release's own model; otherwise the union stays and the distance of the two readings is
    # model form, as a withdrawn effect's is
    not_held = [] if best is candidates[0] else _not_held(best, results)
    chosen = candidates[0] if not_held else best
    bics = np.array([c.bic for c in candidates])
    near = [i for i, c in enumerate(candidates) if c.bic - best.bic < margin]
    wts_m = bic_weights(bics[near])
    # each candidate's ω where the releases read theirs (``measurand``)
    at = [c.omega_at(read_amplitude(results)) for c in candidates]
    w_chosen = at[candidates.index(chosen)][0]
    u_models = float(math.sqrt(sum(w * (at[i][0] - w_chosen) ** 2 for w, i in zip(wts_m, near))))
    weight = dict(zip(near, wts_m))
    table = [{"effects": list(c.shared), "without": sorted(c.dropped), "bic": c.bic, "d_bic": c.bic - best.bic,
              "weight": float(weight.get(i, 0.0)), "omega_n": at[i][0], "omega_n_std": at[i][1],
              "chosen": c is chosen} for i, c in enumerate(candidates)]
    return _Choice(chosen, not_held, u_models, table)


def _releases_apart(fits: list[ModelFit], results: list[IdentificationResult]) -> tuple[np.ndarray, np.ndarray, float]:
    """Each release's ω_n fitted alone with the shared effects (the same model, so that a difference is the
    releases', not the models'), its u (its fit σ with the model-form and calibration terms of its own
    identification), and what the releases share of it (not averaged away), rad/s. Each reads ω where its own
    identification did (``IdentificationResult.omega_n_read_at``: one measurand)."""
    read = [read_at(f, res.omega_n_read_at.amplitude) for f, res in zip(fits, results)]
    w_i = np.array([w for w, _ in read])
    # A release that its own identification gave another model reads another ω_n under the shared
    # one; which of the two is right its record did not decide (the other releases chose the shared
    # effects): their distance is model form of that release
    form_i = np.array([math.hypot(res.omega_n_std_model, w - res.omega_n) for w, res in zip(w_i, results)])
    u_i = np.array([math.sqrt(s**2 + m**2 + (res.omega_n_std_calibration or 0.0) ** 2)
                    for (_, s), m, res in zip(read, form_i, results)])
    wts = 1.0 / u_i**2
    common = float(np.sum(wts * np.array([math.hypot(m, res.omega_n_std_calibration or 0.0)
                                          for m, res in zip(form_i, results)])) / np.sum(wts))
    return w_i, u_i, common


def _fit_jointly(results: list[IdentificationResult], rig: Rig, margin: float) -> JointResult:
    choice = _choose(results, rig, margin)
    chosen = choice.chosen
    w_i, u_i, common = _releases_apart(chosen.fits, results)
    # The joint ω_n weighs each release by its whole uncertainty, which the least squares over the
    # samples cannot know: a release whose model does not hold across it (its model-form term)
    # counts for less. The joint fit's own ω_n is reported beside it (joint_fit).
    wts = 1.0 / u_i**2
    w_joint = float(np.sum(wts * w_i) / np.sum(wts))
    s_joint = float(1.0 / math.sqrt(np.sum(wts)))
    zs = (w_i - w_joint) / u_i
    dof = len(results) - 1
    chi2 = float(np.sum(zs**2))
    p = float(gammaincc(dof / 2.0, chi2 / 2.0))
    k = int(np.argmax(np.abs(zs)))
    pair = max(((abs(w_i[a] - w_i[b]) / math.hypot(u_i[a], u_i[b]), a, b)
                for a in range(len(results)) for b in range(a + 1, len(results))), key=lambda v: v[0])
    birge = math.sqrt(max(chi2 / dof, 1.0))
    own = _own_pair(results)
    flags = [F.RELEASES_DISAGREE] if p < CONSISTENT_P or own[0] > OWN_PAIR_Z else []
    # The joint fit (the laws shared by all samples) and the releases' weighted value estimate the same
    # ω_n: apart beyond their uncertainties, the shared laws do not hold over the releases' amplitudes
    # (a law the model lacks), and which value to believe is not decided by the data: the distance
    # enters u and the result says so.
    w_fit, s_fit = chosen.omega_at(read_amplitude(results))
    u_joint, fit_z = with_joint_fit(w_joint, max(s_joint * birge, common), w_fit, s_fit)
    if fit_z > FIT_APART_Z:
        flags.append(F.MODEL_AMBIGUOUS)
    # shared laws the releases together do not decisively separate: their spread is model form
    u_joint = math.hypot(u_joint, choice.u_models)
    if choice.u_models > s_joint:
        flags.append(F.MODEL_AMBIGUOUS)
    consistency = {
        "chi2": chi2, "dof": dof, "p": p, "birge_ratio": birge, "z": [float(v) for v in zs],
        "omega_n": [float(v) for v in w_i], "u": [float(v) for v in u_i],
        "largest_z": float(zs[k]), "largest_release": results[k].source,
        "pairwise_max": float(pair[0]), "pairwise_releases": [results[pair[1]].source, results[pair[2]].source],
        "own_pairwise_max": own[0], "own_pairwise_releases": [results[own[1]].source, results[own[2]].source],
        "joint_fit": {"omega_n": w_fit, "omega_n_std": s_fit, "z": fit_z,
                      "apart": fit_z > FIT_APART_Z},
        "models": choice.table, "u_models": choice.u_models, "not_held": choice.not_held,
    }
    # the joint ω_n's u already holds the releases' model form and camera view (``common``); the rig's
    # constants come in here. Its degrees of freedom: the releases' when their scatter sets it
    scatter_sets_u = s_joint * birge > common and birge > 1
    return _joint_result(results, rig, chosen, w_joint, s_joint, u_joint, float(dof) if scatter_sets_u else math.inf,
                         consistency, flags)


def _joint_result(results: list[IdentificationResult], rig: Rig, chosen: _SharedModelFit, w_joint: float,
                  s_joint: float, u_joint: float, dof: float, consistency: dict[str, Any],
                  flags: list[str]) -> JointResult:
    """The joint result: J and its budget from the joint ω_n, the shared laws read through the first
    release's model (the same effects for all)."""
    shim = chosen.laws()
    J = inertia(rig, w_joint)
    rms = float(math.sqrt(np.mean(np.concatenate(chosen.residuals) ** 2)))
    return JointResult(
        rig_kind=rig.kind, effects=chosen.shared, omega_n=w_joint, omega_n_std=s_joint, omega_n_u=u_joint,
        J=J, J_std=None if J is None else 2 * J * s_joint / w_joint, J_u=None if J is None else 2 * J * u_joint / w_joint,
        damping=effect_quantities(shim, rig, ("damping",)), stiffness=effect_quantities(shim, rig, ("stiffness",)),
        residual_rms=rms, consistency=consistency,
        flags=tuple(dict.fromkeys(flags + [fl for res in results for fl in res.flags])), releases=tuple(results),
        uncertainty_budget=budgets(rig, w_joint, u_joint, dof=dof, scale_response=None),
    )


def with_joint_fit(w_joint: float, u_joint: float, w_fit: float, s_fit: float) -> tuple[float, float]:
    """The releases' joint ω_n's u (rad/s) once the joint fit's ω_n ± σ (rad/s) is heard, and their distance in σ.

    Within FIT_APART_Z combined σ the two agree and u is unchanged; beyond, their distance enters u.
    """
    z = abs(w_fit - w_joint) / math.hypot(u_joint, s_fit)
    return (math.hypot(u_joint, w_fit - w_joint) if z > FIT_APART_Z else u_joint), z


@dataclass(frozen=True, eq=False)
class _SharedFit:
    """The shared laws as a fit of the first release's model (what ``effect_quantities`` reads)."""

    model: Model
    x: np.ndarray
    cov: np.ndarray

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.cov), 0.0, None))


def joint_value(results: Sequence[IdentificationResult], rig: Rig,
                quantity: str = "J") -> tuple[float, float, dict[str, Any]] | None:
    """The releases' joint value of ``quantity`` (J, J_object or J_object_axis, kg·m²) with its random 1σ
    and the facts of the joint identification; None when the rig gives no J.

    The joint J comes from the joint ω_n; J_object and J_object_axis differ from J by the rig's
    constants, the same for every release (the first release's difference is taken).
    """
    if len(results) < 2 or any(r.J is None or getattr(r, quantity, None) is None for r in results):
        return None
    j = _joint(list(results), rig)
    if j.J is None or j.J_u is None:
        return None
    first = results[0]
    value = j.J - (first.J - getattr(first, quantity))
    facts = {"omega_n": j.omega_n, "omega_n_u": j.omega_n_u, "effects": list(j.effects), "flags": list(j.flags),
             "consistency": _jsonable({k: v for k, v in j.consistency.items() if k != "pairwise_releases"})}
    return float(value), float(j.J_u), facts
