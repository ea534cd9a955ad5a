"""AQDEF (Q-DAS DFQ) export of a recipe's parts: the file automotive SPC systems (Q-DAS qs-STAT, procella, ...)
import, following the AQDEF data format ("Automotive Quality Data Exchange Format", Q-DAS GmbH).

One part type (the recipe) with one characteristic (its measurand: J, J_object or J_object_axis):

* ``K0100`` number of characteristics; ``K1001``/``K1002`` part number and description (recipe name and
  description); ``K2001``/``K2002`` characteristic number and description, ``K2004`` its type (0: variable),
  ``K2022`` decimal places, ``K2101`` nominal, ``K2110``/``K2111`` lower and upper specification limit,
  ``K2142`` unit — in the recipe's display unit (stored values are kg·m²).
* One value line per completed part, fields separated by the DC4 character (0x14) in the AQDEF order
  K0001 value, K0002 attribute (0: valid; 255: the part's verdict is INVALID, the value is not for SPC: the
  mean of its releases, or empty when none gave a value),
  K0004 date/time (dd.mm.yyyy/HH:MM:SS, the appliance's local time as the pages and the report write it; the
  time zone is not written), K0005 events, K0006 batch, K0007 nest, K0008 operator,
  K0009 text (the verdict; an INVALID part's with its first reason, its numbers in the display unit with the
  decimals the pages write them with), K0010 machine (the device ID); then ``K0014`` the part ident (serial).

The file is written in Windows-1252, the code page DFQ readers expect (it has · and ²).
"""

from __future__ import annotations

import datetime as dt
import math
from typing import Any, Iterable, Mapping

from measurement.units import SI, from_si
from service.parts.outcome import PartOutcome, PartSummary
from service.publish.quality import places as shown_places
from service.publish.quality import reason

#: the field separator of a value line (AQDEF: DC4)
FIELD = "\x14"
#: K0002 of a value that is recorded but not for SPC (an INVALID part)
ATTRIBUTE_INVALID = 255
ENCODING = "cp1252"


def _clean(text: Any) -> str:
    """A field value on one line without the separators."""
    return " ".join(str(text or "").replace(FIELD, " ").replace("\x0f", " ").split())


def _decimals(tolerance: float) -> int:
    """Decimal places that resolve a ten-thousandth of the tolerance (SPC charts the spread of the parts, far
    inside the tolerance), at least 3."""
    return max(3, min(15, int(math.ceil(-math.log10(tolerance / 1e4))) if tolerance > 0 else 8))


def _recorded_value(m: Any, part: PartSummary | None) -> float | None:
    """The part's value (kg·m²); of an INVALID part without one, the mean of its releases' values (what was
    measured, marked not for SPC); None when no release gave a value."""
    value = m.part_value
    if value is not None and math.isfinite(value):
        return float(value)
    values = [float(v) for v in (part.values if part is not None else ())
              if isinstance(v, (int, float)) and math.isfinite(v)]
    return sum(values) / len(values) if values else None


def dfq_text(recipe: Mapping[str, Any], parts: Iterable[Any], unit: str = SI) -> str:
    """The DFQ file of ``parts`` (``StoredMeasurement`` rows that completed a part, oldest first) of ``recipe``
    (the payload's recipe dict: name, number, quantity, nominal, lower, upper)."""
    f = from_si(1.0, unit) or 1.0
    nominal, lower, upper = (float(recipe[k]) * f for k in ("nominal", "lower", "upper"))
    places = _decimals(min(upper - nominal, nominal - lower))
    quantity = recipe.get("quantity") or "J"
    lines = ["K0100 1",
             f"K1001 {_clean(recipe.get('name'))}",
             f"K1002 {_clean(recipe.get('description') or ('recipe ' + str(recipe.get('number'))))}",
             "K2001/1 1",
             f"K2002/1 moment of inertia {quantity}",
             "K2004/1 0",
             f"K2022/1 {places}",
             f"K2101/1 {nominal:.{places}f}",
             f"K2110/1 {lower:.{places}f}",
             f"K2111/1 {upper:.{places}f}",
             f"K2142/1 {unit}"]
    for m in parts:
        part = PartOutcome.from_dict(m.payload).part
        value = _recorded_value(m, part)
        when = dt.datetime.fromtimestamp(m.finished_at).astimezone().strftime("%d.%m.%Y/%H:%M:%S")
        invalid = m.part_verdict == "INVALID" or value is None
        attribute = ATTRIBUTE_INVALID if invalid else 0
        # an INVALID part is recorded too, marked not for SPC, with why (its first reason)
        why = next(iter(part.decision.reasons if part is not None else ()), "") if invalid else ""
        why = reason(why, unit, shown_places(recipe, unit)) if why else ""
        fields = [f"{value * f:.{places}f}" if value is not None else "", str(attribute), when, "", "", "",
                  _clean(m.trigger), _clean(f"verdict {m.part_verdict}" + (f": {why}" if why else ""))[:255],
                  _clean(m.device_id)]
        lines.append(FIELD.join(fields))
        lines.append(f"K0014/1 {_clean(m.part_id or m.part_uuid)}")
    return "\r\n".join(lines) + "\r\n"
