"""Recipes (part types) and the parts measured with them.

A recipe is one TOML file per part type in the configuration's recipe
directory (``[recipes] directory``)::

    [recipe]
    name = "rotor-A12"            # unique; names its SPC topic and chart
    number = 12                   # 1…65535: what the PLC writes to register recipe_select
    description = "rotor A, steel"   # optional
    quantity = "J"                # J | J_object (J − tare) | J_object_axis (own axis), as the rig defines it
    nominal = 0.0125              # kg·m²
    tolerance = 1.0e-4            # ± kg·m²   (or tolerance_percent = 0.8, of the nominal)
    releases = 3                  # releases per part (the part's result combines them)
    rig = "rig-A.toml"            # optional: the rig file for this part type (relative to this file)
    declared = ["viscous"]        # optional: the declared model (default: the rig's)
    display_unit = "g·cm²"        # optional: the unit pages and reports show (kg·m², g·cm², kg·mm², lb·in², slug·ft²;
                                  # default: [web] display_unit); stored values stay kg·m²
    display_decimals = 0          # optional: decimals of values and U on pages and reports (default: those that
                                  # resolve a hundredth of the tolerance)

    [decision]                    # optional
    rule = "guard_band"           # guard_band (ISO 14253-1) | simple
    uncertain = "NOK"             # guard band: verdict when conformance is not proven (NOK | INVALID)
    coverage_factor = 2.0         # U = k·u_c

    [quality]                     # optional: when a result is INVALID (for a tensor set: which releases count)
    invalid_flags = ["fit_not_converged", "calibration_due", "negative_inertia"]
    max_J_std = 5.0e-6            # largest 1σ of the quantity, kg·m²   (or max_J_std_percent)
    min_swings = 3.0              # fewest full swings in the fitted window
    consistency_limit = 3.0       # |z| above which releases disagree
    min_valid_releases = 2        # fewest usable releases for a part verdict (default: all of them)
    max_uncertainty_ratio = 0.25  # optional: U at most this fraction of the half-tolerance, else INVALID

A recipe may instead declare a tensor plan: the part's inertia tensor is then
measured as a guided set of orientations (``service.parts.tensor_set``), each
with ``releases`` releases; nominal and tolerance do not apply::

    [recipe]
    name = "bracket-tensor"
    number = 40
    releases = 1                  # releases per orientation

    [tensor.part]                 # as in a `moi tensor` plan file (docs/tensor.md), without rig and traces
    mass = 1.25
    poi_convention = "negative"

    [[tensor.orientation]]
    name = "x"
    axis = [1, 0, 0]
    offset = [0.0, 0.03, -0.02]   # optional, m
    # … at least six

A recipe may make its part a check standard, a reference artifact of
certified J ± U measured at the station like a part (the PLC selects its
number): each complete part is also compared with the certificate, its
normalised error E_n stored as a check standard (as `moi check-standard`
does), and while the newest one has failed the appliance's results carry
``calibration_due``::

    [check_standard]
    reference = 0.012500          # certified value of the recipe quantity, kg·m² (default: the nominal)
    reference_U = 2.0e-5          # its expanded uncertainty (certificate, k = 2), kg·m²
    name = "disc CS-1"            # the artifact (default: the recipe name)

Unless the recipe lists its own ``invalid_flags``, a check standard is not made
INVALID by ``calibration_due``: a passing check is what clears it.

The decision rule and the combination of releases are
``measurement.verdict``'s (documented there). The recipe version is the
SHA-256 of the file's bytes as read (first 16 hex digits): every stored
measurement carries it, so a verdict can be traced to the exact recipe.

The ``[recipe]`` keys are declared once, in ``service.parts.recipe_keys`` (read by this
loader, the editor and the recipes page); the parts measured with a recipe are counted by
``service.parts.tracker.PartTracker``.
"""

from __future__ import annotations

import hashlib
import logging
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from measurement import Rig
from measurement.errors import InvalidInput
from measurement.tensor import TensorPlan
from measurement.tensor_inputs import RigShared
from measurement.units import SI, inertia_unit
from measurement.verdict import RULES, QualityRules, Specification
from service.errors import ConfigError
from service.names import NAMES, name_problem
from service.parts import recipe_keys
from service.parts.outcome import PartOutcome
from service.parts.recipe_keys import EDITABLE
from service.sources.files import read_rig, read_text

log = logging.getLogger("moi.recipes")

#: characters of a part ID (the Modbus block holds 2 per register)
PART_ID_LENGTH = NAMES["part_id"].length


class RecipeError(ConfigError):
    """A recipe file is unusable, or a recipe that does not exist was asked for."""


class RecipeEditError(RecipeError):
    """An edit of a recipe refused, with every problem: ``problems`` {key name: what is wrong} ("" for one of the
    file as a whole); the text names the file and the keys, as a loader's error does."""

    def __init__(self, path: str | Path, problems: Mapping[str, str]) -> None:
        self.problems = dict(problems)
        super().__init__("; ".join(f"{path}: [recipe]{' ' + k if k else ''}: {m}" for k, m in problems.items()))


def check_part_id(text: str) -> str:
    """A part ID as stored: printable ASCII, at most PART_ID_LENGTH characters, no surrounding blanks."""
    if not isinstance(text, str):
        raise InvalidInput(f"part_id must be a string, got {text!r}")
    s = text.strip()
    if s and (problem := name_problem("part_id", s)) is not None:  # empty: no part ID
        raise InvalidInput(problem)
    return s


@dataclass(frozen=True)
class Recipe:
    """One part type. ``spec``/``quality``: the decision (``measurement.verdict``)."""

    name: str
    number: int
    description: str
    path: str
    version: str
    releases: int
    spec: Specification | None  # None for a tensor recipe: no single quantity is judged
    quality: QualityRules
    rig: Rig | None = None
    rig_path: str | None = None
    declared: tuple[str, ...] | None = None
    tensor: TensorPlan | None = None  # the orientations of a guided tensor set
    display_unit: str | None = None   # the unit pages and reports show (None: the set-up's); values stay kg·m²
    display_decimals: int | None = None  # decimals pages and reports show (None: from the tolerance)
    #: a check standard: {name, reference, reference_U} (kg·m²); None for a part type
    check_standard: dict[str, Any] | None = None

    def rig_for(self, device_rig: Rig) -> Rig:
        """The rig a measurement of this part type is identified with."""
        rig = self.rig or device_rig
        return rig.with_declared(self.declared) if self.declared is not None else rig

    def check_rig(self, device_rig: Rig) -> None:
        """RecipeError when the rig it measures with cannot give the recipe's quantity."""
        rig = self.rig_for(device_rig)
        if self.tensor is not None:
            try:
                RigShared.of(rig)
            except InvalidInput as exc:
                raise RecipeError(f"{self.path}: [tensor]: {exc}") from None
        q = self.spec.quantity if self.spec is not None else "J"
        if rig.restoring_constant is None:
            raise RecipeError(f"{self.path}: [recipe] quantity: the rig gives no J (no stiffness, or no mass and "
                              "com_distance); calibrate it or name a calibrated rig")
        if q == "J_object" and rig.tare_inertia is None:
            raise RecipeError(f"{self.path}: [recipe] quantity: J_object needs the rig's tare_inertia")
        if q == "J_object_axis" and rig.object is None:
            raise RecipeError(f"{self.path}: [recipe] quantity: J_object_axis needs the rig's [object] mass and "
                              "axis_offset")

    def to_dict(self) -> dict[str, Any]:
        """What every payload of this recipe carries (JSON-ready)."""
        return {"name": self.name, "number": self.number, "version": self.version, "path": self.path,
                "releases": self.releases, "rig_path": self.rig_path,
                "declared": list(self.declared) if self.declared is not None else None,
                "display_unit": self.display_unit,
                **(self.spec.to_dict() if self.spec is not None else {}), "quality": self.quality.to_dict(),
                **({"tensor": self.tensor.to_dict()} if self.tensor is not None else {}),
                **({"check_standard": dict(self.check_standard)} if self.check_standard is not None else {})}


# --- reading and checking recipe files -------------------------------------------------------------------------
def _schemas() -> dict[str, dict[str, Any]]:
    """The keys of a recipe file: [recipe] from their declarations (``recipe_keys``), [decision] and [quality]
    from the settings they fill (``Specification``, ``QualityRules``: their defaults are the recipe's)."""
    from service.settings.schema import REQUIRED, Key
    from service.settings.schema import doc as _doc
    from service.settings.schema import schema as _schema

    return {
        "recipe": recipe_keys.schema(),
        "decision": _schema(Specification, {
            "rule": _doc("", choices=RULES), "uncertain": _doc("", choices=("NOK", "INVALID")),
            "coverage_factor": _doc("k of U = k·u_c", min=1.0)}),
        "quality": _schema(QualityRules, {
            "invalid_flags": _doc(""), "min_swings": _doc("", min=0.0),
            "consistency_limit": _doc("", min=0, min_open=True),
            "min_valid_releases": _doc("default: all releases", min=1),
            "max_uncertainty_ratio": _doc("largest expanded uncertainty U as a fraction of the half-tolerance "
                                          "(0.25: a test uncertainty ratio of 4); beyond it a result is INVALID",
                                          min=0, min_open=True)},
            defaults={"min_valid_releases": None},
            extra={"max_J_std": Key("float", None, "kg·m²", min=0, min_open=True),
                   "max_J_std_percent": Key("float", None, "% of J", min=0, min_open=True)}),
        "check_standard": {
            "reference": Key("float", None, "certified value of the recipe quantity, kg·m² (default: the nominal)",
                             min=0, min_open=True),
            "reference_U": Key("float", REQUIRED, "its expanded uncertainty (certificate), kg·m²", min=0,
                               min_open=True),
            "name": Key("str", None, "the artifact (default: the recipe name)"),
        },
    }


def _checker(source: str) -> Any:
    """The configuration checker with recipe errors (``RecipeError`` naming the file, table and key)."""
    from service.settings.schema import Checker

    class RecipeChecker(Checker):
        def fail(self, table: str | None, key: str | None, message: str) -> RecipeError:
            where = (f"[{table}]" if table else "") + (f" {key}" if key else "")
            return RecipeError(f"{self.source}: {where + ': ' if where else ''}{message}")

    return RecipeChecker(source)


def load_recipe(path: str | Path) -> Recipe:
    """Read and check one recipe file (``RecipeError`` naming the file, table and key)."""
    from service.sources.files import read_toml

    p = Path(path)
    raw = read_text(p, "recipe file").encode("utf-8")
    try:
        doc = read_toml(p, "recipe file")
    except InvalidInput as exc:
        raise RecipeError(str(exc)) from None
    c = _checker(str(p))
    schemas = _schemas()
    for t in doc:
        if t not in schemas and t != "tensor":
            raise c.fail(None, None, f"unknown table [{t}]; expected [recipe], [decision], [quality], [tensor], "
                         "[check_standard]")
    if "recipe" not in doc:
        raise c.fail(None, None, "missing [recipe] table (name, number, quantity, nominal, tolerance, releases)")
    rec = c.table("recipe", doc["recipe"], schemas["recipe"])
    if (problem := name_problem("recipe", rec["name"])) is not None:
        raise c.fail("recipe", "name", problem)
    tensor = _tensor(c, doc, rec)
    rig, rig_path = _rig(c, p, rec)
    declared = _declared(c, rec, rig)
    quality = _quality(c, doc, c.table("quality", doc.get("quality", {}), schemas["quality"]), rec["releases"])
    spec = None if tensor is not None else \
        _spec(c, rec, c.table("decision", doc.get("decision", {}), schemas["decision"]))
    return Recipe(name=rec["name"], number=rec["number"], description=rec["description"], path=str(p),
                  version=hashlib.sha256(raw).hexdigest()[:16], releases=rec["releases"], spec=spec,
                  quality=quality, rig=rig, rig_path=rig_path, declared=declared, tensor=tensor,
                  display_unit=_display_unit(c, rec), display_decimals=rec["display_decimals"],
                  check_standard=_check_standard(c, doc, rec, tensor))


def _tensor(c: Any, doc: Mapping[str, Any], rec: Mapping[str, Any]) -> TensorPlan | None:
    """The tensor plan of a tensor recipe (None: the recipe judges one quantity, which needs its nominal)."""
    if "tensor" not in doc:
        if rec["nominal"] is None:
            raise c.fail("recipe", "nominal", "missing (kg·m²)")
        return None
    if not isinstance(doc["tensor"], dict):
        raise c.fail("tensor", None, "expected a table: [tensor.part] and [[tensor.orientation]]")
    try:
        tensor = TensorPlan.from_dict(doc["tensor"])
    except InvalidInput as exc:
        raise c.fail("tensor", None, str(exc)) from None
    if any(rec[k] is not None for k in ("nominal", "tolerance", "tolerance_percent")) or "decision" in doc:
        raise c.fail("recipe", "nominal", "a tensor recipe's result is the tensor: nominal, tolerance and "
                     "[decision] do not apply")
    return tensor


def _spec(c: Any, rec: Mapping[str, Any], dec: Mapping[str, Any]) -> Specification:
    """The specification of a recipe that judges one quantity: nominal ± tolerance (absolute or in %)."""
    if (rec["tolerance"] is None) == (rec["tolerance_percent"] is None):
        raise c.fail("recipe", "tolerance", "give exactly one of tolerance (± kg·m²) or tolerance_percent "
                     "(± % of nominal)")
    nominal = rec["nominal"]
    tol = rec["tolerance"] if rec["tolerance"] is not None else nominal * rec["tolerance_percent"] / 100.0
    if tol >= nominal:
        raise c.fail("recipe", "tolerance", f"expected less than the nominal {nominal:g} kg·m², got {tol:g}")
    try:
        return Specification.symmetric(rec["quantity"], nominal, tol, **dec)
    except InvalidInput as exc:
        raise c.fail("recipe", None, str(exc)) from None


def _rig(c: Any, p: Path, rec: Mapping[str, Any]) -> tuple[Rig | None, str | None]:
    """The recipe's own rig file, read (None: the set-up's rig)."""
    if rec["rig"] is None:
        return None, None
    rig_path = str((p.parent / rec["rig"]).resolve())
    try:
        return read_rig(rig_path), rig_path
    except InvalidInput as exc:
        raise c.fail("recipe", "rig", str(exc)) from None


def _declared(c: Any, rec: Mapping[str, Any], rig: Rig | None) -> tuple[str, ...] | None:
    """The declared model: known effects that resolve on the rig they are used with."""
    from measurement.effects import EFFECTS

    declared = rec["declared"]
    if declared is None:
        return None
    for e in declared:
        if e not in EFFECTS:
            raise c.fail("recipe", "declared", f"unknown effect {e!r}; expected names from {', '.join(EFFECTS)}")
    try:
        (rig or Rig(kind="torsion")).with_declared(declared)
    except InvalidInput as exc:
        raise c.fail("recipe", "declared", str(exc)) from None
    return tuple(declared)


def _display_unit(c: Any, rec: Mapping[str, Any]) -> str | None:
    if rec["display_unit"] is None:
        return None
    try:
        return inertia_unit(rec["display_unit"])
    except InvalidInput as exc:
        raise c.fail("recipe", "display_unit", str(exc)) from None


def _quality(c: Any, doc: Mapping[str, Any], qual: Mapping[str, Any], releases: int) -> QualityRules:
    """When a release or a part is INVALID."""
    if qual["max_J_std"] is not None and qual["max_J_std_percent"] is not None:
        raise c.fail("quality", "max_J_std", "give max_J_std (kg·m²) or max_J_std_percent, not both")
    # a part passes only on all its releases unless the recipe says how many may be excluded
    min_valid = qual["min_valid_releases"] if qual["min_valid_releases"] is not None else releases
    if min_valid > releases:
        raise c.fail("quality", "min_valid_releases", f"expected at most releases = {releases}, got {min_valid}")
    pct = qual["max_J_std_percent"]
    invalid_flags = tuple(qual["invalid_flags"])
    if "check_standard" in doc and "invalid_flags" not in doc.get("quality", {}):
        # the check standard is what clears a calibration_due its failure raised: it must not be refused for it
        invalid_flags = tuple(f for f in invalid_flags if f != "calibration_due")
    return QualityRules(invalid_flags=invalid_flags, max_std=qual["max_J_std"],
                        max_std_relative=None if pct is None else pct / 100.0, min_swings=qual["min_swings"],
                        consistency_limit=qual["consistency_limit"], min_valid_releases=min_valid,
                        max_uncertainty_ratio=qual["max_uncertainty_ratio"])


def _check_standard(c: Any, doc: Mapping[str, Any], rec: Mapping[str, Any],
                    tensor: TensorPlan | None) -> dict[str, Any] | None:
    """A check standard's certificate: {name, reference, reference_U} (None: a part type)."""
    if "check_standard" not in doc:
        return None
    if tensor is not None:
        raise c.fail("check_standard", None, "a tensor recipe cannot be a check standard")
    cs = c.table("check_standard", doc["check_standard"], _schemas()["check_standard"])
    if cs["name"] is not None and (problem := name_problem("check_standard", cs["name"])) is not None:
        raise c.fail("check_standard", "name", problem)
    return {"name": cs["name"] or rec["name"],
            "reference": cs["reference"] if cs["reference"] is not None else rec["nominal"],
            "reference_U": cs["reference_U"]}


#: the append-only log of recipe edits, in the state directory
RECIPE_AUDIT_FILE = "recipe-audit.log"


def edit_recipe(recipe: Recipe, typed: Mapping[str, str], unit: str = SI,
                shown_in: str | None = None) -> tuple[Recipe, dict[str, tuple[Any, Any]]]:
    """Set the editable [recipe] keys (``recipe_keys.EDITABLE``) of ``typed`` (text as typed, an inertia in
    ``unit``, the display unit chosen in the same form; empty removes an optional key) in ``recipe``'s file,
    keeping its comments and layout; the new file goes through ``load_recipe`` before it replaces the old one in
    one step (RecipeEditError naming every key refused, the file unchanged). An inertia left as the form showed
    it (in ``shown_in``, the unit it was opened in) keeps its value. Returns the re-read recipe and
    {key: (before, after)} of what changed."""
    import tomlkit

    from service.sources.files import write_atomic

    path = Path(recipe.path)
    doc = tomlkit.parse(read_text(path, "recipe file"))
    table = doc["recipe"]
    changes: dict[str, tuple[Any, Any]] = {}
    problems: dict[str, str] = {}
    for key in EDITABLE:
        if key.name not in typed:
            continue
        before = table.get(key.name)
        before = before.unwrap() if hasattr(before, "unwrap") else before
        text = str(typed[key.name]).strip()
        if text in {key.typed(before, u) or "" for u in (unit, shown_in or unit)}:
            continue  # as shown: unchanged, whatever a conversion to the unit and back would round
        try:
            after = key.parse(text, unit)
        except ValueError as exc:
            problems[key.name] = str(exc)
            continue
        if after == before:
            continue
        changes[key.name] = (before, after)
        if after is None:
            table.pop(key.name, None)
        else:
            table[key.name] = after
    if problems:
        raise RecipeEditError(path, problems)
    if not changes:
        return recipe, changes
    text = tomlkit.dumps(doc)
    trial = path.with_name(f".{path.name}.edit")
    try:
        write_atomic(trial, text, "recipe file")
        load_recipe(trial)  # the edited file must read as a recipe before it replaces the old one
    except RecipeError as exc:
        said = str(exc).replace(str(trial), str(path))
        found = re.match(rf"{re.escape(str(path))}: \[recipe\] (\w+): (.*)", said, re.S)
        raise RecipeEditError(path, {found[1]: found[2]} if found else {"": said.replace(f"{path}: ", "")}) from None
    finally:
        trial.unlink(missing_ok=True)
    write_atomic(path, text, "recipe file")
    return load_recipe(path), changes


def recipe_values(recipe: Recipe, unit: str = SI) -> dict[str, str | None]:
    """The editable keys as ``recipe``'s file holds them, as text a person types, an inertia in ``unit`` (None:
    not in the file)."""
    import tomllib

    rec = tomllib.loads(read_text(Path(recipe.path), "recipe file")).get("recipe") or {}
    return {k.name: k.typed(rec.get(k.name), unit) for k in EDITABLE}


def recipe_version(recipe: Recipe) -> str:
    """A short digest of ``recipe``'s file as it is now: an edit opened on another version was opened before a
    change."""
    return hashlib.sha256(read_text(Path(recipe.path), "recipe file").encode("utf-8")).hexdigest()[:16]


def audit_recipe(log_path: str | Path, who: str, recipe: Recipe, changes: Mapping[str, tuple[Any, Any]],
                 when: str) -> str:
    """Append one line to the recipe audit log (``when`` ISO time, who, recipe, file, key: before → after)
    and return it; the log is only ever appended to."""
    what = "; ".join(f"{k}: {'–' if b is None else b} → {'–' if a is None else a}" for k, (b, a) in changes.items())
    line = f"{when}\t{who}\t{recipe.name}\t{Path(recipe.path).name}\t{what}\n"
    with open(log_path, "a", encoding="utf-8") as f:
        f.write(line)
    return line


@dataclass(frozen=True)
class RecipeBook:
    """Every recipe of the recipe directory, by name and by number."""

    directory: str | None
    recipes: tuple[Recipe, ...] = ()

    @classmethod
    def load(cls, directory: str | Path | None) -> "RecipeBook":
        """All ``*.toml`` files of ``directory`` (None: no recipes). Duplicate names or numbers are errors."""
        if directory is None:
            return cls(None)
        d = Path(directory)
        if not d.is_dir():
            raise RecipeError(f"recipe directory {str(d)!r} not found")
        recipes = [load_recipe(p) for p in sorted(d.glob("*.toml"))]
        seen: dict[Any, str] = {}
        for r in recipes:
            for key in (("name", r.name), ("number", r.number)):
                if key in seen:
                    raise RecipeError(f"{r.path}: [recipe] {key[0]}: {key[1]!r} is already used by {seen[key]}")
                seen[key] = r.path
        return cls(str(d), tuple(recipes))

    def find(self, key: str | int) -> Recipe:
        """A recipe by name or number (a string of digits is a number)."""
        for r in self.recipes:
            if r.name == key or (isinstance(key, int) and r.number == key) or (isinstance(key, str) and key.isdigit()
                                                                              and r.number == int(key)):
                return r
        known = ", ".join(f"{r.number} {r.name}" for r in self.recipes) or "none"
        raise RecipeError(f"no recipe {key!r} (known: {known})")

    @property
    def numbers(self) -> frozenset[int]:
        return frozenset(r.number for r in self.recipes)


# --- SPC of a recipe's parts ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RecipeSpc:
    """The SPC of one recipe's completed parts (oldest first). INVALID parts are left out and counted."""

    recipe: str
    summary: Any  # measurement.spc.SpcSummary
    parts: tuple[str, ...]            # part IDs (or part UUIDs) of the plotted points
    versions: tuple[str, ...]         # recipe versions seen (more than one: the recipe changed in the series)
    invalid_left_out: int
    first: float                      # finished_at of the first and last part, Unix s
    last: float
    quantity: str
    finished: tuple[float, ...] = ()  # finished_at of each plotted part, Unix s

    def to_dict(self, include_points: bool = False) -> dict[str, Any]:
        return {"recipe": self.recipe, "quantity": self.quantity, "versions": list(self.versions),
                "parts": len(self.parts), "invalid_left_out": self.invalid_left_out,
                "first": self.first, "last": self.last, **self.summary.to_dict(include_points)}


#: parts in the SPC summary the daemon publishes after each part (the latest ones)
SPC_WINDOW = 100


def recipe_spc(store: Any, recipe: str, *, since: float | None = None, until: float | None = None,
               chart: str = "auto", limit: int | None = None) -> RecipeSpc | None:
    """SPC of ``recipe``'s completed parts in the store (None with fewer than 2 usable parts).

    chart "auto": X̄–R when every part combined the same number (2…10) of releases, else I-MR
    of the part values; "I-MR", "Xbar-R" or "Xbar-S" to choose. Limits: the newest part's recipe.
    limit: only the latest ``limit`` completed parts.
    """
    from measurement.spc import D2, individuals, xbar_r, xbar_s

    rows = list(reversed(store.list(limit=limit, recipe=recipe, parts_only=True, since=since, until=until, full=True)))
    read = [(m, PartOutcome.from_dict(m.payload)) for m in rows if m.part_verdict != "INVALID" and m.payload]
    done = [(m, o) for m, o in read if o.part is not None and o.part.value is not None]
    if len(done) < 2:
        return None
    usable = [m for m, _ in done]
    spec = done[-1][1].recipe or {}
    lsl, usl = spec["lower"], spec["upper"]
    # a used release always has its value
    groups = [[v for i in part.used if (v := part.values[i]) is not None] for part in (o.part for _, o in done)
              if part is not None]
    sizes = {len(g) for g in groups}
    use_xbar = chart == "Xbar-R" or (chart == "auto" and len(sizes) == 1 and next(iter(sizes)) in D2)
    if chart == "Xbar-S":
        summary = xbar_s(groups, lsl, usl)
    else:
        summary = xbar_r(groups, lsl, usl) if use_xbar else individuals([m.part_value for m in usable], lsl, usl)
    versions = tuple(dict.fromkeys(m.recipe_version for m in usable if m.recipe_version))
    return RecipeSpc(recipe, summary, tuple(m.part_id or m.part_uuid or "" for m in usable), versions,
                     len(rows) - len(usable), usable[0].finished_at, usable[-1].finished_at, spec["quantity"],
                     tuple(m.finished_at for m in usable))
