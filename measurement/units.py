"""Units of moment of inertia a page or a report may show. Values are computed and stored in SI (kg·m²);
a display unit only changes how a number is written.

Conversion factors are exact from the international yard and pound (1959): 1 lb = 0.45359237 kg,
1 in = 0.0254 m, 1 ft = 0.3048 m; the slug is 1 lbf·s²/ft = 0.45359237 · 9.80665 / 0.3048 kg.
"""

from __future__ import annotations

import math

from .errors import InvalidInput

_LB, _IN, _FT = 0.45359237, 0.0254, 0.3048
_SLUG = _LB * 9.80665 / _FT

#: display unit → how many of it make one kg·m²
INERTIA_UNITS: dict[str, float] = {
    "kg·m²": 1.0,
    "g·cm²": 1e3 * 1e4,
    "kg·mm²": 1e6,
    "lb·in²": 1.0 / (_LB * _IN**2),
    "slug·ft²": 1.0 / (_SLUG * _FT**2),
}

#: the same units written in ASCII (what a configuration file may say)
ASCII_NAMES: dict[str, str] = {name.replace("·", "*").replace("²", "^2"): name for name in INERTIA_UNITS}

SI = "kg·m²"


class UnitError(InvalidInput):
    """A display unit this appliance does not know."""


def inertia_unit(name: str) -> str:
    """The display unit ``name`` (``kg·m²`` or its ASCII form ``kg*m^2``), UnitError for an unknown one."""
    key = ASCII_NAMES.get(name, name)
    if key not in INERTIA_UNITS:
        raise UnitError(f"unknown unit of inertia {name!r}; expected one of {', '.join(INERTIA_UNITS)} "
                        f"(or {', '.join(ASCII_NAMES)})")
    return key


def from_si(value: float | None, unit: str) -> float | None:
    """``value`` kg·m² in ``unit`` (None and non-finite values stay None)."""
    if value is None or not math.isfinite(value):
        return None
    return value * INERTIA_UNITS[inertia_unit(unit)]
