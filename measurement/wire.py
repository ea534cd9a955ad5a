"""How a number comes back from the result JSON: one that the JSON cannot hold (NaN, ±∞) is written
null (``result._num``), and null is read back as NaN (``read_number``)."""

from __future__ import annotations

import math
from typing import Any


def read_number(v: Any) -> Any:
    """A number of the JSON as written (int or float, never converted), NaN where it held null."""
    return math.nan if v is None else v
