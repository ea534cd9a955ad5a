"""The inertia tensor of a part from its moments of inertia about several axes.

Pure and hardware-free: axes and inertias in, a tensor with its covariance out.
SI units: kg·m² for inertias, kg for mass, m for offsets; axes in the part's
own frame.

The method
----------
The moment of inertia about a unit axis n through the centre of mass is the
quadratic form I_n = nᵀ·T·n of the inertia matrix T, linear in its six
entries x = (Txx, Tyy, Tzz, Txy, Txz, Tyz):

    I_n = a(n)·x,   a(n) = [nx², ny², nz², 2·nx·ny, 2·nx·nz, 2·ny·nz].

A *plan* of N ≥ 6 axes whose rows a(n_i) have rank 6 determines x. The
measured inertias b (one per orientation) carry a covariance V: each
orientation's own uncertainty on the diagonal, and the parts every
orientation shares (the rig's stiffness calibration, which scales every J
alike; the tare of the fixture; the part's mass in the parallel-axis step) off
it. Generalised least squares gives

    x = (AᵀV⁻¹A)⁻¹·AᵀV⁻¹·b,   cov(x) = (AᵀV⁻¹A)⁻¹

(weighted least squares when V is diagonal), χ² = rᵀV⁻¹r with N − 6 degrees of
freedom, and each orientation's normalised residual r_i / √(V − A·cov(x)·Aᵀ)_ii.

The parallel-axis step
----------------------
A swing axis that misses the centre of mass by d (the centre of mass seen from
any point of the axis) adds m·(|d|² − (n·d)²): the squared distance of the
centre of mass from the axis times the mass (Steiner). It is removed from the
measured inertia before the solve, with the mass's uncertainty (common to
every orientation) and the offset's (each orientation's own) in V.

Products of inertia
-------------------
``tensor`` is always the inertia matrix T (nᵀ·T·n is the inertia about n, its
off-diagonal entries are −∫xy dm). The reported components Ixy, Ixz, Iyz follow
the plan's convention: "negative" reports T's entries (Ixy = −∫xy dm),
"positive" reports the products themselves (Ixy = +∫xy dm = −Txy).

Principal moments and axes
--------------------------
The eigen-decomposition of T. The moments' uncertainty is propagated to first
order (∂λ_k/∂x = a(v_k)); the axes' angular uncertainty is the angle that
contains the coverage probability (95.45 % for k = 2) of axes drawn by a seeded
Monte Carlo from N(x, cov(x)). Two principal moments equal within their
uncertainty leave their axes undetermined in their plane: the angle says so.

Checks (each a flag with its reason): ``tensor_inconsistent`` (χ² beyond its
99 % point, N > 6; names the orientation with the largest normalised
residual), ``tensor_unphysical`` (a principal moment ≤ 0, or I1 + I2 < I3,
beyond U), ``orientation_excluded`` (an orientation whose releases were all
INVALID was left out; the rest must still determine the tensor).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from . import flags as F
from .errors import TensorError
from .result import IdentificationResult, _jsonable
from .rig import Rig
from .tensor_inputs import AxisReading, RigShared, axis_reading
from .verdict import QualityRules

#: the six components, in the order of the rows a(n), the covariance and the Modbus block
COMPONENTS = ("Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz")
#: products of inertia: "negative" Ixy = −∫xy dm (the inertia matrix's entry), "positive" Ixy = +∫xy dm
CONVENTIONS = ("negative", "positive")
MIN_ORIENTATIONS = 6
#: a plan whose design matrix is worse conditioned than this cannot determine the tensor in floating point
MAX_CONDITION = 1.0e6
#: χ² beyond this point of its distribution flags the set inconsistent
CHI2_PROBABILITY = 0.99
COVERAGE_FACTOR = 2.0
MONTE_CARLO_DRAWS = 4000
MONTE_CARLO_SEED = 20240601
#: a rig whose constants add nothing the orientations share (each reading's u is all there is)
_NOTHING_SHARED = RigShared()

_S = 1.0 / math.sqrt(2.0)
#: the usual six: the part's x, y, z and the bisectors of the xy, xz and yz planes
DEFAULT_AXES: tuple[tuple[str, tuple[float, float, float]], ...] = (
    ("x", (1.0, 0.0, 0.0)), ("y", (0.0, 1.0, 0.0)), ("z", (0.0, 0.0, 1.0)),
    ("xy", (_S, _S, 0.0)), ("xz", (_S, 0.0, _S)), ("yz", (0.0, _S, _S)),
)
_D = 1.0 / math.sqrt(3.0)
#: the six and three body diagonals: every axis is checked by the others (no two residuals move
#: together), so a mis-mounted or mis-typed one is named, not just noticed
NINE_AXES: tuple[tuple[str, tuple[float, float, float]], ...] = DEFAULT_AXES + (
    ("x+y-z", (_D, _D, -_D)), ("x-y-z", (_D, -_D, -_D)), ("x-y+z", (_D, -_D, _D)),
)

_PLAN_KEYS = {"part", "orientation"}
_PART_KEYS = {"name", "mass", "mass_std", "poi_convention"}
_ORIENTATION_KEYS = {"name", "axis", "offset", "offset_std"}


def design_row(axis: Sequence[float] | np.ndarray) -> np.ndarray:
    """a(n) = [nx², ny², nz², 2nxny, 2nxnz, 2nynz] of a unit axis: I_n = a(n)·x."""
    nx, ny, nz = (float(v) for v in axis)
    return np.array([nx * nx, ny * ny, nz * nz, 2 * nx * ny, 2 * nx * nz, 2 * ny * nz])


def matrix_of(x: Sequence[float] | np.ndarray) -> np.ndarray:
    """The 3×3 inertia matrix from (Txx, Tyy, Tzz, Txy, Txz, Tyz)."""
    xx, yy, zz, xy, xz, yz = (float(v) for v in x)
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def entries_of(T: Any) -> np.ndarray:
    """(Txx, Tyy, Tzz, Txy, Txz, Tyz) of a symmetric 3×3 inertia matrix."""
    T = np.asarray(T, dtype=float)
    return np.array([T[0, 0], T[1, 1], T[2, 2], T[0, 1], T[0, 2], T[1, 2]])


def convention_signs(convention: str) -> np.ndarray:
    """Multiplies the matrix entries into the convention's components (and back: it is its own inverse)."""
    if convention not in CONVENTIONS:
        raise TensorError(f"poi_convention must be one of {', '.join(CONVENTIONS)}, got {convention!r}")
    s = 1.0 if convention == "negative" else -1.0
    return np.array([1.0, 1.0, 1.0, s, s, s])


def components_of(T: Any, convention: str) -> dict[str, float]:
    """Ixx … Iyz of the inertia matrix T in the convention ("negative" | "positive"), kg·m²."""
    return dict(zip(COMPONENTS, (entries_of(T) * convention_signs(convention)).tolist()))


def matrix_from_components(components: Mapping[str, float], convention: str) -> np.ndarray:
    """The inertia matrix from Ixx … Iyz given in the convention (the inverse of ``components_of``)."""
    missing = [c for c in COMPONENTS if c not in components]
    if missing:
        raise TensorError(f"components {', '.join(missing)} missing; expected {', '.join(COMPONENTS)}")
    return matrix_of(np.array([float(components[c]) for c in COMPONENTS]) * convention_signs(convention))


def axis_offset_inertia(mass: float, axis: Sequence[float] | np.ndarray, offset: Sequence[float] | np.ndarray) -> float:
    """m·(|d|² − (n·d)²), kg·m²: what a swing axis n (unit) that misses the centre of mass by d (m) adds."""
    n = np.asarray(axis, dtype=float)
    d = np.asarray(offset, dtype=float)
    return float(mass * (d @ d - (n @ d) ** 2))


def _vector(name: str, value: Any, *, unit: bool) -> tuple[float, float, float]:
    if (not isinstance(value, (list, tuple)) or len(value) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
        raise TensorError(f"{name} must be three numbers [x, y, z], got {value!r}")
    v = np.array(value, dtype=float)
    if not np.all(np.isfinite(v)):
        raise TensorError(f"{name} must be finite numbers, got {value!r}")
    if unit:
        norm = float(np.linalg.norm(v))
        if norm < 1e-9:
            raise TensorError(f"{name} is a zero vector: a swing axis needs a direction")
        v = v / norm
    return (float(v[0]), float(v[1]), float(v[2]))


def _nonnegative(name: str, value: Any, unit: str, *, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or value < 0 or (positive and value == 0):
        raise TensorError(f"{name} must be a number {'>' if positive else '>='} 0 {unit}, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class Orientation:
    """One mounting of the part: the swing axis in the part's frame and where the centre of mass sits.

    name: how the operator and the report call it. axis: unit vector (normalised on input).
    offset: the centre of mass seen from a point of the swing axis, part frame, m (None: on the axis).
    offset_std: 1σ of each of the offset's components, m.
    """

    name: str
    axis: tuple[float, float, float]
    offset: tuple[float, float, float] | None = None
    offset_std: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"name": self.name, "axis": list(self.axis)}
        if self.offset is not None:
            d["offset"] = list(self.offset)
            d["offset_std"] = self.offset_std
        return d


@dataclass(frozen=True)
class TensorPlan:
    """The orientations of a set and what is known of the part.

    part: its name. mass, mass_std: kg (mass needed when any orientation has an offset).
    poi_convention: "negative" | "positive" (see the module docstring).
    The plan is checked on construction: ≥ 6 orientations, unit axes whose rows
    a(n) have rank 6 and a condition number below MAX_CONDITION, an offset only with a mass.
    """

    orientations: tuple[Orientation, ...]
    part: str = "part"
    mass: float | None = None
    mass_std: float = 0.0
    poi_convention: str = "negative"

    def __post_init__(self) -> None:
        convention_signs(self.poi_convention)
        if len(self.orientations) < MIN_ORIENTATIONS:
            raise TensorError(f"a tensor plan needs at least {MIN_ORIENTATIONS} orientations, got "
                              f"{len(self.orientations)}")
        names = [o.name for o in self.orientations]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise TensorError(f"orientation names must differ; {', '.join(map(repr, dup))} used twice")
        offsets = [o.name for o in self.orientations if o.offset is not None and any(self.offset_vector(o))]
        if offsets and self.mass is None:
            raise TensorError(f"orientation(s) {', '.join(offsets)} give an offset but [part] has no mass: the "
                              "parallel-axis step m·(|d|² − (n·d)²) needs it")
        rank, cond = plan_geometry([o.axis for o in self.orientations])
        if rank < 6 or cond > MAX_CONDITION:
            raise TensorError(f"the plan's axes cannot determine the tensor (rank {rank} of 6, condition number "
                              f"{cond:.3g}): add axes out of the planes and bisectors already used")

    @property
    def condition_number(self) -> float:
        """Of the design matrix A (rows a(n)): how much the plan's geometry amplifies the inertias' errors."""
        return plan_geometry([o.axis for o in self.orientations])[1]

    @staticmethod
    def offset_vector(o: Orientation) -> tuple[float, float, float]:
        return o.offset if o.offset is not None else (0.0, 0.0, 0.0)

    def index(self, name: str) -> int:
        for i, o in enumerate(self.orientations):
            if o.name == name:
                return i
        raise TensorError(f"no orientation named {name!r} in the plan; it has {', '.join(o.name for o in self.orientations)}")

    @classmethod
    def default(cls, **kwargs: Any) -> "TensorPlan":
        """The usual six orientations (x, y, z and the 45° bisectors of xy, xz, yz), on the centre of mass."""
        return cls(tuple(Orientation(n, a) for n, a in DEFAULT_AXES), **kwargs)

    @classmethod
    def nine(cls, **kwargs: Any) -> "TensorPlan":
        """The six and three body diagonals (NINE_AXES): 3 degrees of freedom that check every axis."""
        return cls(tuple(Orientation(n, a) for n, a in NINE_AXES), **kwargs)

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any], extra_orientation_keys: Sequence[str] = (),
                  extra_keys: Sequence[str] = ()) -> "TensorPlan":
        """The plan from its TOML document: ``[part]`` and ``[[orientation]]`` tables.

        extra_orientation_keys / extra_keys: keys a caller reads itself (the traces of
        `moi tensor`, the rig file), accepted here and ignored.
        """
        unknown = set(doc) - _PLAN_KEYS - set(extra_keys)
        if unknown:
            raise TensorError(f"tensor plan: unknown key(s) {sorted(unknown)}; expected "
                              f"{sorted(_PLAN_KEYS | set(extra_keys))}")
        part = doc.get("part", {})
        if not isinstance(part, Mapping):
            raise TensorError("tensor plan: [part] must be a table (name, mass, mass_std, poi_convention)")
        unknown = set(part) - _PART_KEYS
        if unknown:
            raise TensorError(f"tensor plan: unknown key(s) in [part]: {sorted(unknown)}; expected {sorted(_PART_KEYS)}")
        name = part.get("name", "part")
        if not isinstance(name, str) or not name.strip():
            raise TensorError(f"tensor plan: [part] name must be a non-empty string, got {name!r}")
        mass = None if "mass" not in part else _nonnegative("[part] mass", part["mass"], "kg", positive=True)
        mass_std = _nonnegative("[part] mass_std", part.get("mass_std", 0.0), "kg")
        convention = part.get("poi_convention", "negative")
        if convention not in CONVENTIONS:
            raise TensorError(f"tensor plan: [part] poi_convention must be \"negative\" (Ixy = −∫xy dm) or "
                              f"\"positive\" (Ixy = +∫xy dm), got {convention!r}")
        rows = doc.get("orientation")
        if not isinstance(rows, list) or not all(isinstance(r, Mapping) for r in rows):
            raise TensorError("tensor plan: no [[orientation]] tables; expected at least "
                              f"{MIN_ORIENTATIONS}, each with axis = [x, y, z]")
        orientations = []
        allowed = _ORIENTATION_KEYS | set(extra_orientation_keys)
        for i, row in enumerate(rows, 1):
            unknown = set(row) - allowed
            if unknown:
                raise TensorError(f"tensor plan: orientation {i}: unknown key(s) {sorted(unknown)}; expected {sorted(allowed)}")
            if "axis" not in row:
                raise TensorError(f"tensor plan: orientation {i} has no axis; expected axis = [x, y, z] in the part's frame")
            label = row.get("name", default_name(i))
            if not isinstance(label, str) or not label.strip():
                raise TensorError(f"tensor plan: orientation {i}: name must be a non-empty string, got {label!r}")
            axis = _vector(f"orientation {label!r}: axis", row["axis"], unit=True)
            offset = _vector(f"orientation {label!r}: offset", row["offset"], unit=False) if "offset" in row else None
            offset_std = _nonnegative(f"orientation {label!r}: offset_std", row.get("offset_std", 0.0), "m")
            orientations.append(Orientation(label, axis, offset, offset_std))
        return cls(tuple(orientations), name, mass, mass_std, convention)

    def to_dict(self) -> dict[str, Any]:
        part: dict[str, Any] = {"name": self.part, "poi_convention": self.poi_convention}
        if self.mass is not None:
            part["mass"] = self.mass
            part["mass_std"] = self.mass_std
        return {"part": part, "orientation": [o.to_dict() for o in self.orientations]}


def default_name(i: int) -> str:
    """The name of the i-th orientation (1-based) when the plan gives none."""
    return f"o{i}"


def plan_geometry(axes: Sequence[Sequence[float]]) -> tuple[int, float]:
    """Rank and condition number of the design matrix of these unit axes (condition ∞ when rank < 6)."""
    A = np.array([design_row(a) for a in axes])
    s = np.linalg.svd(A, compute_uv=False)
    if s.size < 6:
        return int(s.size), math.inf
    rank = int(np.sum(s > s[0] * 1e-12))
    return rank, (float(s[0] / s[-1]) if s[-1] > s[0] * 1e-12 else math.inf)


# -- the solve ---------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class TensorResult:
    """The inertia tensor about the centre of mass, part frame, with everything it rests on. SI units.

    tensor: the inertia matrix T (nᵀ·T·n = inertia about n), kg·m². components: Ixx … Iyz in
    ``poi_convention``; cov: their 6×6 covariance (order COMPONENTS); U = k·σ per component.
    principal_moments (ascending) with U; principal_axes: unit vectors (rows, a right-handed frame)
    with their angular uncertainty in degrees (Monte Carlo, coverage of k). chi2, dof, chi2_limit
    (its 99 % point). orientations: per orientation what was measured, the parallel-axis
    correction, the fitted nᵀ·T·n and the normalised residual. flags with their reasons.
    """

    part: str
    poi_convention: str
    tensor: np.ndarray
    components: dict[str, float]
    cov: np.ndarray
    U: dict[str, float]
    coverage_factor: float
    principal_moments: tuple[float, float, float]
    principal_moments_U: tuple[float, float, float]
    principal_axes: tuple[tuple[float, float, float], ...]
    principal_axes_U_deg: tuple[float, float, float]
    condition_number: float
    chi2: float
    dof: int
    chi2_limit: float | None
    orientations: tuple[dict[str, Any], ...]
    flags: tuple[str, ...]
    reasons: dict[str, str]
    mass: float | None = None
    monte_carlo: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return _jsonable({
            "kind": "tensor",
            "part": self.part,
            "poi_convention": self.poi_convention,
            "tensor": self.tensor,
            "components": self.components,
            "tensor_cov": self.cov,
            "tensor_U": self.U,
            "coverage_factor": self.coverage_factor,
            "principal_moments": list(self.principal_moments),
            "principal_moments_U": list(self.principal_moments_U),
            "principal_axes": [list(a) for a in self.principal_axes],
            "principal_axes_U_deg": list(self.principal_axes_U_deg),
            "condition_number": self.condition_number,
            "chi2": self.chi2, "dof": self.dof, "chi2_limit": self.chi2_limit,
            "mass": self.mass,
            "orientations": list(self.orientations),
            "flags": list(self.flags),
            "reasons": dict(self.reasons),
            "monte_carlo": self.monte_carlo,
        })

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), ensure_ascii=False, allow_nan=False)


def _principal(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ascending principal moments and their axes (columns), each axis's largest component positive,
    the third made so the frame is right-handed."""
    lam, V = np.linalg.eigh(T)
    for k in range(2):
        if V[np.argmax(np.abs(V[:, k])), k] < 0:
            V[:, k] = -V[:, k]
    V[:, 2] = np.cross(V[:, 0], V[:, 1])
    return lam, V


def _sqrt_psd(C: np.ndarray) -> np.ndarray:
    w, Q = np.linalg.eigh((C + C.T) / 2)
    return Q * np.sqrt(np.clip(w, 0.0, None))


@dataclass(frozen=True, eq=False)
class _Measured:
    """The orientations a solve uses: their axes' design rows A, the part's inertia about each axis as
    measured (J_axis), its parallel-axis correction and what is left about the centre of mass (b = A·x), with
    the covariance V of b (each orientation's own u and offset on the diagonal, the rig and the mass shared)."""

    used: list[int]
    excluded: dict[int, str]
    condition_number: float
    A: np.ndarray
    J_axis: np.ndarray
    correction: np.ndarray
    b: np.ndarray
    V: np.ndarray


@dataclass(frozen=True, eq=False)
class _Fit:
    """The generalised least squares of b = A·x: x, its covariance C, χ² on dof and each orientation's
    normalised residual (None where the fit leaves it no freedom)."""

    x: np.ndarray
    C: np.ndarray
    chi2: float
    dof: int
    z: list[float | None]


def _usable(plan: TensorPlan, readings: Sequence[AxisReading | None]) -> tuple[list[int], dict[int, str], float]:
    """(the orientations used, the others with why, the plan's condition number over those used)."""
    if len(readings) != len(plan.orientations):
        raise TensorError(f"the plan has {len(plan.orientations)} orientations but {len(readings)} readings were given")
    used: list[int] = []
    excluded: dict[int, str] = {}
    for i, r in enumerate(readings):
        if r is None or r.invalid is not None or r.value is None or r.u is None:
            excluded[i] = "not measured" if r is None else (r.invalid or "no value")
        else:
            used.append(i)
    rank, cond = plan_geometry([plan.orientations[i].axis for i in used])
    if rank < 6 or cond > MAX_CONDITION:
        raise TensorError(f"the orientations left ({len(used)}: {', '.join(plan.orientations[i].name for i in used)}) "
                          f"cannot determine the tensor (rank {rank} of 6); excluded: "
                          + "; ".join(f"{plan.orientations[i].name} ({why})" for i, why in excluded.items()))
    return used, excluded, cond


def _measured(plan: TensorPlan, readings: Sequence[AxisReading | None], shared: RigShared) -> _Measured:
    used, excluded, cond = _usable(plan, readings)
    own = [readings[i] for i in used]
    ors = [plan.orientations[i] for i in used]
    A = np.array([design_row(o.axis) for o in ors])
    m = plan.mass or 0.0
    J_axis = np.array([float(r.value) for r in own if r is not None and r.value is not None])
    u_own = np.array([float(r.u) for r in own if r is not None and r.u is not None])
    # of each used orientation, the rig's J (which its stiffness calibration scales): the part's where not given
    rig_J = np.array([float(r.rig_inertia if r.rig_inertia is not None else r.value) for r in own
                      if r is not None and r.value is not None])
    # the parallel-axis step and its sensitivities to the mass (common) and the offset (own)
    dperp2 = np.array([axis_offset_inertia(1.0, o.axis, plan.offset_vector(o)) for o in ors])
    correction = m * dperp2
    grad_d = np.array([2 * m * (np.asarray(plan.offset_vector(o)) - (np.asarray(o.axis) @ plan.offset_vector(o))
                                * np.asarray(o.axis)) for o in ors])
    u_offset2 = np.array([o.offset_std**2 for o in ors]) * np.sum(grad_d**2, axis=1)
    V = np.diag(u_own**2 + u_offset2) + shared.common_covariance(rig_J) + plan.mass_std**2 * np.outer(dperp2, dperp2)
    if not np.all(np.diag(V) > 0):
        bad = [o.name for o, v in zip(ors, np.diag(V)) if not v > 0]
        raise TensorError(f"orientation(s) {', '.join(bad)} have no uncertainty: a tensor's covariance needs each "
                          "orientation's J with its σ")
    return _Measured(used, excluded, cond, A, J_axis, correction, J_axis - correction, V)


def _least_squares(d: _Measured) -> _Fit:
    L = np.linalg.cholesky(d.V)
    At = np.linalg.solve(L, d.A)
    bt = np.linalg.solve(L, d.b)
    x, *_ = np.linalg.lstsq(At, bt, rcond=None)
    C = np.linalg.inv(At.T @ At)
    C = (C + C.T) / 2
    resid = d.b - d.A @ x
    dof = len(d.used) - 6
    chi2 = float(np.sum((bt - At @ x) ** 2)) if dof else 0.0  # rounding's, not the data's, when exactly determined
    var_r = np.diag(d.V - d.A @ C @ d.A.T)
    z = [float(ri / math.sqrt(vr)) if vr > 1e-9 * vii else None for ri, vr, vii in zip(resid, var_r, np.diag(d.V))]
    return _Fit(x, C, chi2, dof, z)


def _axes_U(fit: _Fit, Vec: np.ndarray, coverage: float, draws: int, seed: int) -> np.ndarray:
    """The principal axes' angular uncertainty (degrees, at ``coverage``): a seeded Monte Carlo over N(x, C)."""
    rng = np.random.default_rng(seed)
    xs = fit.x + rng.standard_normal((draws, 6)) @ _sqrt_psd(fit.C).T
    Ts = np.empty((draws, 3, 3))
    for (i, j), k in (((0, 0), 0), ((1, 1), 1), ((2, 2), 2), ((0, 1), 3), ((0, 2), 4), ((1, 2), 5)):
        Ts[:, i, j] = Ts[:, j, i] = xs[:, k]
    _, Vs = np.linalg.eigh(Ts)
    cosines = np.abs(np.einsum("nik,ik->nk", Vs, Vec))
    angles = np.degrees(np.arccos(np.clip(cosines, 0.0, 1.0)))
    return np.quantile(angles, coverage, axis=0)


def _inconsistent(plan: TensorPlan, d: _Measured, fit: _Fit, chi2_limit: float) -> str:
    """Why χ² is beyond its limit, naming the orientation of the largest normalised residual."""
    size = {k: abs(zk) for k, zk in enumerate(fit.z) if zk is not None}  # orientation: |normalised residual|
    worst = max(size, key=size.__getitem__, default=None)
    who = ""
    if worst is not None:
        o = plan.orientations[d.used[worst]]
        who = (f"; orientation {o.name!r} (axis [{', '.join(f'{v:.4g}' for v in o.axis)}]) has the largest "
               f"normalised residual {fit.z[worst]:+.2f}: a mis-mounted or mis-typed axis?")
    return f"χ² = {fit.chi2:.3g} for {fit.dof} dof, beyond its 99 % point {chi2_limit:.3g}{who}"


def _unphysical(lam: np.ndarray, lam_U: np.ndarray, grads: np.ndarray, C: np.ndarray, coverage_factor: float) -> str:
    """Why the principal moments no body can have ("": none)."""
    out = []
    if lam[0] + lam_U[0] <= 0:
        out.append(f"the smallest principal moment {lam[0]:.4g} ± {lam_U[0]:.2g} kg·m² is ≤ 0")
    g_tri = grads[0] + grads[1] - grads[2]
    tri, tri_U = float(lam[0] + lam[1] - lam[2]), coverage_factor * math.sqrt(float(g_tri @ C @ g_tri))
    if tri + tri_U < 0:
        out.append(f"I1 + I2 − I3 = {tri:.4g} ± {tri_U:.2g} kg·m² < 0 (the triangle inequality)")
    return "; ".join(out)


def _rows(plan: TensorPlan, readings: Sequence[AxisReading | None], d: _Measured, fit: _Fit) -> list[dict[str, Any]]:
    """Per orientation: what was measured, the parallel-axis correction, the fitted nᵀ·T·n, the residual."""
    rows: list[dict[str, Any]] = []
    k_used = {i: k for k, i in enumerate(d.used)}
    for i, o in enumerate(plan.orientations):
        row: dict[str, Any] = o.to_dict()
        rdg = readings[i]
        if rdg is not None:
            row["releases"] = rdg.to_dict()
        if i in d.excluded:
            row["excluded"] = d.excluded[i]
            row["fitted"] = float(design_row(o.axis) @ fit.x)
        else:
            k = k_used[i]
            row.update({"J_axis": float(d.J_axis[k]), "parallel_axis": float(d.correction[k]), "J": float(d.b[k]),
                        "u": float(math.sqrt(d.V[k, k])), "fitted": float(d.A[k] @ fit.x),
                        "normalised_residual": fit.z[k]})
        rows.append(row)
    return rows


def solve(plan: TensorPlan, readings: Sequence[AxisReading | None], shared: RigShared = _NOTHING_SHARED, *,
          coverage_factor: float = COVERAGE_FACTOR, draws: int = MONTE_CARLO_DRAWS,
          seed: int = MONTE_CARLO_SEED) -> TensorResult:
    """The tensor from one reading per orientation of the plan (None or ``invalid``: excluded and named).

    Raises TensorError when the orientations left cannot determine the tensor.
    """
    from scipy.stats import chi2 as chi2_dist

    d = _measured(plan, readings, shared)
    fit = _least_squares(d)
    signs = convention_signs(plan.poi_convention)
    cov = fit.C * np.outer(signs, signs)
    U = coverage_factor * np.sqrt(np.diag(cov))
    T = matrix_of(fit.x)
    lam, Vec = _principal(T)
    grads = np.array([design_row(Vec[:, k]) for k in range(3)])
    lam_U = coverage_factor * np.sqrt(np.einsum("ki,ij,kj->k", grads, fit.C, grads))
    coverage = math.erf(coverage_factor / math.sqrt(2))
    ang_U = _axes_U(fit, Vec, coverage, draws, seed)

    reasons: dict[str, str] = {}
    chi2_limit = float(chi2_dist.ppf(CHI2_PROBABILITY, fit.dof)) if fit.dof > 0 else None
    if chi2_limit is not None and fit.chi2 > chi2_limit:
        reasons[F.TENSOR_INCONSISTENT] = _inconsistent(plan, d, fit, chi2_limit)
    if unphysical := _unphysical(lam, lam_U, grads, fit.C, coverage_factor):
        reasons[F.TENSOR_UNPHYSICAL] = unphysical
    if d.excluded:
        reasons[F.ORIENTATION_EXCLUDED] = "; ".join(f"{plan.orientations[i].name}: {why}"
                                                    for i, why in d.excluded.items())
    return TensorResult(
        part=plan.part, poi_convention=plan.poi_convention, tensor=T,
        components=dict(zip(COMPONENTS, (fit.x * signs).tolist())), cov=cov, U=dict(zip(COMPONENTS, U.tolist())),
        coverage_factor=coverage_factor,
        principal_moments=tuple(lam.tolist()), principal_moments_U=tuple(lam_U.tolist()),
        principal_axes=tuple(tuple(Vec[:, k].tolist()) for k in range(3)),
        principal_axes_U_deg=tuple(ang_U.tolist()),
        condition_number=d.condition_number, chi2=fit.chi2, dof=fit.dof, chi2_limit=chi2_limit,
        orientations=tuple(_rows(plan, readings, d, fit)), flags=tuple(reasons), reasons=reasons, mass=plan.mass,
        monte_carlo={"draws": draws, "seed": seed, "coverage": coverage},
    )


def solve_results(plan: TensorPlan, results: Sequence[Sequence[IdentificationResult]], rig: Rig,
                  rules: QualityRules = QualityRules(), **kwargs: Any) -> TensorResult:
    """The tensor from each orientation's releases' results on ``rig``."""
    shared = RigShared.of(rig)
    return solve(plan, [axis_reading(r, shared, rules) for r in results], shared, **kwargs)
