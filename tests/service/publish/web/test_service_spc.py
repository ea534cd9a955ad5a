"""`moi spc` numbers against hand computation on known series, its PNG, and `moi results --part`."""

from __future__ import annotations

import json
import math
from typing import Any, Callable, Sequence

import pytest

from service.cli import main
from service.persistence.store import Store

RECIPE = {"name": "disc", "number": 3, "version": "abc123", "quantity": "J", "nominal": 12.0, "lower": 8.0,
          "upper": 16.0, "coverage_factor": 2.0}


def _returning(payload: dict[str, Any]) -> Callable[[str, int], dict[str, Any]]:
    """A ``build_payload`` for a payload made beforehand (whatever the uuid and sequence number)."""
    return lambda uuid, seq: payload


def add_part(store: Store, t: float, serial: str, values: Sequence[float], verdict: str = "OK",
             recipe: dict = RECIPE) -> None:
    """Store the releases of one part as the daemon does (the last release carries the part)."""
    n = len(values)
    mean = sum(values) / n
    for i, v in enumerate(values, start=1):
        complete = i == n
        part = {"mean": mean, "U": 0.1, "values": values, "used": list(range(n)), "excluded": [],
                "quantity": "J", "reasons": [], "verdict": verdict} if complete else None
        release = {"index": i, "of": n, "verdict": "OK", "value": v, "u_c": 0.05, "quantity": "J", "reasons": [],
                   "part_uuid": f"pu-{serial}"}
        payload: dict[str, Any] = {"part_id": serial, "recipe": recipe, "release": release, "part": part,
                   "verdict": verdict if complete else None, "calibration": {"date": "2026-01-01", "due": False}}
        store.record(status="ok", trigger="modbus", device_id="d", software_version="test", started_at=t,
                     finished_at=t + i, result={"J": v, "flags": []}, build_payload=_returning(payload),
                     part={"part_id": serial, "part_uuid": f"pu-{serial}", "recipe": recipe["name"],
                           "recipe_version": recipe["version"], "release_index": i, "releases": n,
                           "verdict": "OK", "part_verdict": verdict if complete else None,
                           "part_value": mean if complete else None, "part_U": 0.1 if complete else None})


def run_json(capsys, *args: str) -> list[dict]:
    assert main(["spc", *args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_individuals_numbers_by_hand_and_the_png(tmp_path, capsys):
    with Store(tmp_path / "s") as store:
        for k, v in enumerate([10, 12, 11, 13, 12]):
            add_part(store, 1.7e9 + 100 * k, f"SN-{k}", [v])
        add_part(store, 1.7e9 + 900, "SN-bad", [30], verdict="INVALID")  # left out, counted
    [doc] = run_json(capsys, "--state-dir", str(tmp_path / "s"), "--recipe", "disc", "--out", str(tmp_path / "png"))
    sigma = 1.5 / 1.128  # MR̄ = (2 + 1 + 2 + 1)/4
    assert doc["chart"] == "I-MR" and doc["parts"] == 5 and doc["invalid_left_out"] == 1
    assert doc["mean"] == pytest.approx(11.6) and doc["sigma_within"] == pytest.approx(sigma)
    assert doc["ucl"] == pytest.approx(11.6 + 3 * sigma) and doc["lcl"] == pytest.approx(11.6 - 3 * sigma)
    assert doc["cp"] == pytest.approx(8 / (6 * sigma)) and doc["cpk"] == pytest.approx(3.6 / (3 * sigma))
    assert doc["sigma_overall"] == pytest.approx(math.sqrt(1.3)) and doc["outside"] == []
    png = tmp_path / "png" / "spc-disc.png"
    assert doc["png"] == str(png) and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    # the text report says the same
    assert main(["spc", "--state-dir", str(tmp_path / "s"), "--no-plot"]) == 0
    out = capsys.readouterr().out
    assert "I-MR chart: 5 points" in out and "Cp 1" in out and "INVALID parts left out: 1" in out


def test_xbar_r_numbers_by_hand_since_a_date(tmp_path, capsys):
    with Store(tmp_path / "s") as store:
        add_part(store, 1.6e9, "old", [50, 50, 50])  # before --since: not charted
        for k, g in enumerate([[10, 11, 12], [11, 13, 12], [12, 12, 15]]):
            add_part(store, 1.7e9 + 100 * k, f"SN-{k}", g)
    [doc] = run_json(capsys, "--state-dir", str(tmp_path / "s"), "--since", "2023-11-01", "--no-plot")
    rbar = 7 / 3
    assert doc["chart"] == "Xbar-R" and doc["subgroup"] == 3 and doc["points"] == [11, 12, 13]
    assert doc["mean"] == pytest.approx(12) and doc["ucl"] == pytest.approx(12 + 1.023 * rbar, rel=1e-4)
    assert doc["range_ucl"] == pytest.approx(2.574 * rbar, rel=1e-3)
    assert doc["cpk"] == pytest.approx(4 / (3 * rbar / 1.693))


def test_spc_with_too_few_parts_is_one_line(tmp_path, capsys):
    with Store(tmp_path / "s") as store:
        add_part(store, 1.7e9, "only", [10])
    assert main(["spc", "--state-dir", str(tmp_path / "s"), "--recipe", "disc"]) == 2
    assert "fewer than 2 usable parts" in capsys.readouterr().err


def test_results_by_part_shows_releases_verdict_recipe_version_and_calibration(tmp_path, capsys):
    with Store(tmp_path / "s") as store:
        add_part(store, 1.7e9, "SN-7", [10, 11, 12], verdict="NOK")
        add_part(store, 1.7e9 + 50, "SN-8", [10])
    assert main(["results", "--state-dir", str(tmp_path / "s"), "--part", "SN-7"]) == 0
    out = capsys.readouterr().out
    assert "part SN-7: 3 measurement(s)" in out and "version abc123" in out and "release 3/3" in out
    assert "part verdict NOK" in out and "calibration 2026-01-01" in out and "SN-8" not in out
    assert main(["results", "--state-dir", str(tmp_path / "s"), "--part", "SN-7", "--json"]) == 0
    docs = json.loads(capsys.readouterr().out)
    assert [d["release_index"] for d in docs] == [1, 2, 3] and docs[-1]["part_verdict"] == "NOK"
    assert docs[-1]["recipe_version"] == "abc123" and docs[-1]["calibration"]["date"] == "2026-01-01"
    assert main(["export", "--state-dir", str(tmp_path / "s"), "--part", "SN-7"]) == 0
    lines = capsys.readouterr().out.splitlines()
    header = lines[0].split(",")
    last = dict(zip(header, lines[-1].split(",")))
    assert len(lines) == 4 and last["part_verdict"] == "NOK" and last["recipe_version"] == "abc123"
    assert last["calibration_date"] == "2026-01-01" and last["part_id"] == "SN-7"
    assert main(["results", "--state-dir", str(tmp_path / "s"), "--part", "nope"]) == 2
    capsys.readouterr()
    assert main(["results", "--state-dir", str(tmp_path / "s")]) == 0
    assert "[SN-7 disc 3/3 OK part NOK]" in capsys.readouterr().out
