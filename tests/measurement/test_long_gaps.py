"""A record with a long gap between two samples costs what its samples cost, never what its time span would:
the even grid of the smoothing tools and the simulated window are bounded by the number of samples."""

from __future__ import annotations

import json
import math
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from measurement.signal import MAX_GRID_PER_SAMPLE, resample_uniform

REPO = Path(__file__).resolve().parents[2]
#: address space of the `moi identify` child: far below what a 1e6 s gap on a 10 ms grid took (some 20 GB)
MEMORY_LIMIT = 3 * 2**30


def _swing_with_gap(gap: float, n: int = 2000, dt: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    i = np.arange(n)
    t = i * dt + np.where(i >= n // 2, gap, 0.0)
    return t, 0.2 * np.cos(i * 0.05) * np.exp(-i * 0.001)


def test_the_even_grid_is_bounded_by_the_samples_not_the_span():
    t, y = _swing_with_gap(1e9)
    tu, yu, dt = resample_uniform(t, y)
    assert tu.size <= MAX_GRID_PER_SAMPLE * t.size and yu.size == tu.size
    assert dt == (t[-1] - t[0]) / (MAX_GRID_PER_SAMPLE * t.size)
    even = np.arange(100) * 0.01
    assert resample_uniform(even, even)[0] is even  # an even record as it was


def test_identify_a_record_with_a_huge_gap_under_a_memory_limit(tmp_path):
    t, y = _swing_with_gap(1e6)
    path = tmp_path / "gap.csv"
    path.write_text("t,angle\n" + "".join(f"{a!r},{b!r}\n" for a, b in zip(t.tolist(), y.tolist())))
    proc = subprocess.run([sys.executable, "-m", "service.cli", "identify", str(path), "--rig",
                           str(REPO / "examples" / "torsion_rig.toml"), "--json"], cwd=str(REPO),
                          capture_output=True, text=True, timeout=300,
                          preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT)))
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    result = json.loads(proc.stdout)
    assert "window_cut_at_gap" in result["flags"]  # the part before the gap is what can be fitted
    assert result["omega_n"] == pytest.approx(5.0, rel=1e-3) and math.isfinite(result["J"])
