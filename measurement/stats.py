"""Statistics over repeated measurements (repeatability: mean, sample standard deviation)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .errors import InvalidInput


@dataclass(frozen=True)
class Repeatability:
    """n repeated values: mean, sample standard deviation (ddof = 1), standard error of the mean."""

    n: int
    mean: float
    std: float
    sem: float
    spread: float  # max − min


def repeatability(values: Sequence[float]) -> Repeatability:
    v = np.asarray(values, dtype=float)
    if v.size < 2 or not np.all(np.isfinite(v)):
        raise InvalidInput(f"repeatability needs at least 2 finite values, got {v.size}")
    std = float(np.std(v, ddof=1))
    return Repeatability(int(v.size), float(v.mean()), std, std / math.sqrt(v.size), float(np.ptp(v)))
