"""The keys of a recipe file's ``[recipe]`` table, each declared once: its name, type, unit, bounds, default and
doc, and whether a quality engineer edits it on the recipes page. The loader checks a file against them
(``schema``), the editor reads what is typed with them (``RecipeKey.parse``, ``RecipeKey.typed``), and the page
labels its form with them (``RecipeKey.label``, ``RecipeKey.inputmode``). pymeasure's ``Parameter`` is the model:
one object per setting that knows how it is named, shown and checked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from decimal import Decimal
from typing import Any

from measurement.units import INERTIA_UNITS, SI, from_si
from measurement.verdict import QUANTITIES


@dataclass(frozen=True)
class RecipeKey:
    """One key of ``[recipe]``. kind: "str", "int", "float", "path" or "strlist" (the configuration schema's);
    default: the value without the key (required: it must be given); unit: what the
    file's number is in, as the page writes it after the name ("" none); min/max (min_open: min excluded) and
    choices: what the loader accepts; editable: on the recipes page; either: one of an either-or pair (the page
    offers it only where the file gives it); listed: what the page offers to choose from (typed freely in a file).
    A key whose unit is kg·m² is an inertia: the page shows and takes it in the recipe's display unit."""

    name: str
    kind: str
    default: Any = None
    doc: str = ""
    unit: str = ""
    min: float | None = None
    max: float | None = None
    min_open: bool = False
    choices: tuple[Any, ...] | None = None
    editable: bool = False
    either: bool = False
    required: bool = False
    listed: tuple[str, ...] | None = None

    @property
    def inertia(self) -> bool:
        return self.unit == SI

    @property
    def label(self) -> str:
        """The form's label: the name in words, with its unit."""
        return self.label_in(SI)

    def label_in(self, unit: str) -> str:
        """The form's label on a recipe shown in ``unit`` (an inertia is edited in it)."""
        shown = unit if self.inertia else self.unit
        return self.name.replace("_", " ") + (f" ({shown})" if shown else "")

    @property
    def inputmode(self) -> str:
        """The keyboard a phone offers for it."""
        return "numeric" if self.kind == "int" else "text"

    def parse(self, text: str, unit: str = SI) -> Any:
        """The value of what a person typed (None: empty, the key removed), an inertia typed in ``unit`` given in
        kg·m²; a decimal comma is read as a point. ValueError saying what was expected, then what is out of
        bounds (the loader checks the file as a whole afterwards)."""
        text = text.strip()
        if text == "":
            return None
        if self.kind not in ("int", "float"):
            return text
        if "," in text:
            if "." in text or text.count(",") > 1:
                raise ValueError(f"expected a number with one decimal separator, got {text!r}")
            text = text.replace(",", ".")
        try:
            value: Any = int(text) if self.kind == "int" else float(text)
        except ValueError:
            raise ValueError(f"expected a {'whole ' if self.kind == 'int' else ''}number, got {text!r}") from None
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f"expected a finite number, got {text!r}")
        self._bounds(value)
        return value / INERTIA_UNITS[unit] if self.inertia else value

    def _bounds(self, value: float) -> None:
        if self.min is not None and (value <= self.min if self.min_open else value < self.min):
            raise ValueError(f"expected {'above' if self.min_open else 'at least'} {self.min:g}, got {value:g}")
        if self.max is not None and value > self.max:
            raise ValueError(f"expected at most {self.max:g}, got {value:g}")

    def typed(self, value: Any, unit: str = SI) -> str | None:
        """A file's value as text a person types (an inertia in ``unit``, to 12 significant digits; numbers
        without e-notation; None: not in the file)."""
        if value is None:
            return None
        if self.inertia and isinstance(value, (int, float)):
            return f"{Decimal(f'{from_si(float(value), unit):.12g}').normalize():f}"
        return f"{Decimal(repr(value)):f}" if isinstance(value, float) else str(value)


#: the ``[recipe]`` table, in the order a file and the page list it
RECIPE_KEYS: tuple[RecipeKey, ...] = (
    RecipeKey("name", "str", None, "unique; names the SPC topic and chart", required=True),
    RecipeKey("number", "int", None, "what the PLC writes to recipe_select", min=1, max=0xFFFF, required=True),
    RecipeKey("description", "str", "", ""),
    RecipeKey("quantity", "str", "J", "", choices=QUANTITIES),
    RecipeKey("nominal", "float", None, "required unless the recipe declares [tensor]", "kg·m²", min=0,
              min_open=True, editable=True),
    RecipeKey("tolerance", "float", None, "± kg·m²", "kg·m²", min=0, min_open=True, editable=True, either=True),
    RecipeKey("tolerance_percent", "float", None, "± % of the nominal", "± %", min=0, min_open=True, editable=True,
              either=True),
    RecipeKey("releases", "int", 1, "releases per part", min=1, max=20, editable=True),
    RecipeKey("rig", "path", None, "rig file of this part type, relative to the recipe file"),
    RecipeKey("declared", "strlist", None, "declared model"),
    RecipeKey("display_unit", "str", None, "unit the pages and reports show (values stay kg·m²)", editable=True,
              listed=tuple(INERTIA_UNITS)),
    RecipeKey("display_decimals", "int", None, "decimals pages and reports show values and U with (default: those "
              "that resolve a hundredth of the tolerance)", min=0, max=12, editable=True),
)

#: the keys a quality engineer edits on the recipes page (what a part type's decision rests on)
EDITABLE: tuple[RecipeKey, ...] = tuple(k for k in RECIPE_KEYS if k.editable)


def schema() -> dict[str, Any]:
    """The ``[recipe]`` table as the configuration checker reads it (``service.settings.schema.Key``)."""
    from service.settings.schema import REQUIRED, Key

    return {k.name: Key(k.kind, REQUIRED if k.required else k.default, k.doc or k.unit,
                        choices=k.choices, min=k.min, max=k.max, min_open=k.min_open) for k in RECIPE_KEYS}
