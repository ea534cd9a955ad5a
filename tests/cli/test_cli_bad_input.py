"""Bad input to the CLI is one line on stderr and exit status 2, never a traceback (exit 1 is a bug):
output paths that are not regular files, plots, degenerate traces, deep TOML, huge inputs, calibration
files; and the rough edges of everyday use (spreadsheet CSV, a closed pipe)."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from service.cli import main
from service.persistence.store import Store

REPO = Path(__file__).resolve().parents[2]
RIG = str(REPO / "examples" / "torsion_rig.toml")


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def write_swing(path: Path, dt: float = 0.01, n: int = 2000, bom: bool = False) -> Path:
    # with a sensor's noise (1e-4 rad, seeded): a noise-free record sends the identification hunting for
    # structure at the rounding level, seconds per command, which these tests of the command line do not ask
    noise = 1e-4 * np.random.default_rng(3).standard_normal(n)
    rows = [f"{i * dt!r},{0.2 * math.cos(i * 0.05) * math.exp(-i * 0.001) + float(noise[i])!r}" for i in range(n)]
    path.write_bytes(("\ufeff" if bom else "").encode() + ("t,angle\n" + "\n".join(rows) + "\n").encode())
    return path


@pytest.fixture
def store_dir(tmp_path):
    d = tmp_path / "state"
    with Store(d) as s:
        t = np.linspace(0.0, 60.0, 12_000)
        s.record(status="ok", trigger="button", device_id="rig", software_version="t", started_at=1e9,
                 finished_at=1e9 + 60, result={"J": 0.0125, "flags": []},
                 build_payload=lambda u, q: {"uuid": u, "seq": q, "J": 0.0125, "timestamp": 1e9},
                 trace_t=t, trace_angle=0.2 * np.cos(5 * t))
    return d


def test_export_refuses_targets_that_are_not_regular_files_and_leaves_nothing_behind(store_dir, tmp_path, capsys):
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    link = tmp_path / "link.csv"
    link.symlink_to(victim)
    (tmp_path / "adir").mkdir()
    for target, expected in ((tmp_path / "adir", "is a directory"), (link, "symbolic link"),
                             (Path("/dev/null"), "not a regular file"), (tmp_path / "nodir" / "x.csv", "does not exist")):
        assert main(["export", "--state-dir", str(store_dir), "--out", str(target)]) == 2
        assert expected in one_error_line(capsys)
    assert victim.read_text() == "keep me" and link.is_symlink()
    assert main(["export", "--state-dir", str(store_dir), "--out", str(tmp_path / "all.csv")]) == 0
    assert (tmp_path / "all.csv").read_text().startswith("seq,uuid")
    assert not list(tmp_path.glob("*.tmp")) and not list(tmp_path.glob(".*.tmp"))


def test_identify_plot_paths_are_checked_first_and_the_result_survives_a_failed_plot(tmp_path, capsys, monkeypatch):
    trace = write_swing(tmp_path / "swing.csv")
    assert main(["identify", str(trace), "--rig", RIG, "--plot", str(tmp_path / "plot.jpg")]) == 2
    assert "ending in .png, .svg, .pdf" in one_error_line(capsys)
    assert main(["identify", str(trace), "--rig", RIG, "--plot", str(tmp_path / "no" / "plot.png")]) == 2
    assert "does not exist" in one_error_line(capsys)

    from service.commands import identify as identify_cmd
    from service.errors import InputFileError

    def disk_full(path, data, what="output file"):
        raise InputFileError(f"cannot write {what} {str(path)!r}: No space left on device")

    monkeypatch.setattr(identify_cmd, "write_atomic", disk_full)
    assert main(["identify", str(trace), "--rig", RIG, "--json", "--plot", str(tmp_path / "plot.png")]) == 2
    captured = capsys.readouterr()
    assert '"J"' in captured.out and "No space left" in captured.err  # the result was printed first
    monkeypatch.undo()
    # the picture's format follows the file name: SVG here (PNG and PDF the same way)
    assert main(["identify", str(trace), "--rig", RIG, "--plot", str(tmp_path / "plot.svg")]) == 0
    svg = (tmp_path / "plot.svg").read_text()
    assert svg.lstrip().startswith("<?xml") and "<svg" in svg and "residual [rad]" in svg


@pytest.mark.parametrize("case", ["timestamps 1e-300 apart", "angles in counts", "deep TOML rig", "/dev/zero"])
def test_degenerate_and_hostile_inputs_are_one_line(tmp_path, capsys, case):
    rig = RIG
    if case == "timestamps 1e-300 apart":
        source = str(write_swing(tmp_path / "t.csv", dt=1e-300, n=400))
    elif case == "angles in counts":
        source = str(tmp_path / "t.csv")
        Path(source).write_text("t,angle\n" + "".join(f"{i * 0.01},{1e300 * (-1) ** i}\n" for i in range(400)))
    elif case == "deep TOML rig":
        source = str(write_swing(tmp_path / "t.csv"))
        rig = str(tmp_path / "deep.toml")
        Path(rig).write_text("a = " + "[" * 3000 + "]" * 3000 + "\n")
    else:
        if not os.path.exists("/dev/zero"):
            pytest.skip("no /dev/zero")
        source = "/dev/zero"
    assert main(["identify", source, "--rig", rig]) == 2
    one_error_line(capsys)


def test_a_trace_as_spreadsheet_programs_write_it_is_read(tmp_path, capsys):
    assert main(["identify", str(write_swing(tmp_path / "excel.csv", bom=True)), "--rig", RIG, "--json"]) == 0
    assert '"J"' in capsys.readouterr().out


@pytest.mark.parametrize(("body", "expected"), [
    ("reference = [1, 2]\n", "expected a [[reference]] table"),
    ('[[reference]]\nname = "a"\nomega = 7.0\nzeta = -0.06\nadded_inertia = nan\n', "finite number"),
])
def test_bad_calibration_files_are_one_line(tmp_path, capsys, body, expected):
    cal = tmp_path / "cal.toml"
    cal.write_text(body)
    assert main(["calibrate", str(cal), "--rig", RIG]) == 2
    assert expected in one_error_line(capsys)


def test_a_stale_register_map_document_is_exit_2(tmp_path, capsys):
    doc = tmp_path / "modbus.md"
    doc.write_text("# an old map\n")
    assert main(["modbus-map", "--check", str(doc)]) == 2
    assert "differs" in one_error_line(capsys)


def test_a_reader_that_goes_away_is_no_traceback(store_dir):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    p = subprocess.Popen([sys.executable, "-m", "service.cli", "export", "--state-dir", str(store_dir), "--trace", "1"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=str(REPO), env=env)
    assert p.stdout is not None and p.stderr is not None
    p.stdout.close()  # like `| head` that already exited: every write meets a closed pipe
    err = p.stderr.read().decode()
    assert p.wait(60) == 141 and "Traceback" not in err, err


def test_results_list_and_show_J_object(tmp_path, capsys):
    from measurement import Pendulum, Rig, identify, simulate_trace

    rig = Rig(kind="torsion", stiffness=0.3651, tare_inertia=4.5043e-3, declared=("viscous",))
    r = identify(simulate_trace(Pendulum(rig, 0.0125, {"viscous": {"c": 1.5e-4}}), theta0=0.25, duration=5,
                                rate=100, noise_std=1e-4, seed=3), rig)
    assert r.J_object is not None
    d = tmp_path / "s"
    with Store(d) as s:
        s.record(status="ok", trigger="button", device_id="rig", software_version="t", started_at=1e9,
                 finished_at=1e9 + 1, result=r.to_dict(),
                 build_payload=lambda u, q: {"uuid": u, "seq": q, "timestamp": 1e9, **r.to_dict()})
    assert main(["results", "--state-dir", str(d)]) == 0
    out = capsys.readouterr().out
    assert "J_object" in out.splitlines()[0] and f"{r.J_object:.7g}" in out
    assert main(["results", "1", "--state-dir", str(d)]) == 0
    assert f"J_object      = {r.J_object:.7g} ± {r.J_object_std:.2g}" in capsys.readouterr().out


def test_the_license_is_an_spdx_expression():
    import tomllib

    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    assert isinstance(project["license"], str)  # a table prints a deprecation banner on every install


def test_calibrate_help_shows_the_file_format_and_the_shipped_example_calibrates(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["calibrate", "--help"])
    helptext = capsys.readouterr().out
    assert "[[reference]]" in helptext and "examples/calibration.toml" in helptext
    rig = tmp_path / "rig.toml"
    rig.write_text((REPO / "examples" / "torsion_rig.toml").read_text())
    assert main(["calibrate", str(REPO / "examples" / "calibration.toml"), "--rig", str(rig), "--out", str(rig)]) == 0
    text = rig.read_text()
    assert "# k, N·m/rad" in text and "[calibration]" in text  # the user's comments survive the rewrite
    from service.sources.files import read_rig
    assert read_rig(rig).stiffness == pytest.approx(0.3651, rel=1e-4)


def test_json_and_csv_exports_carry_the_same_iso_times(store_dir, tmp_path):
    import csv
    import json

    assert main(["export", "--state-dir", str(store_dir), "--format", "json", "--out", str(tmp_path / "a.json")]) == 0
    assert main(["export", "--state-dir", str(store_dir), "--out", str(tmp_path / "a.csv")]) == 0
    doc = json.loads((tmp_path / "a.json").read_text())[0]
    row = next(csv.DictReader((tmp_path / "a.csv").open()))
    assert doc["finished_at"] == row["finished_at"] == "2001-09-09T01:47:40.000+00:00"
    assert doc["unit"] == row["unit"] == "kg·m²"


def test_a_gpio_library_that_is_installed_but_fails_says_why_not_install_it(monkeypatch):
    import drivers.backend as backend
    from drivers.errors import DriverConfigError

    class BrokenLgpio:
        name = "lgpio"

        def load(self):
            def factory():
                raise OSError(30, "Read-only file system: '.lgd-nfy0'")
            return factory

    monkeypatch.setattr(backend, "entry_points", lambda group: [BrokenLgpio()])
    with pytest.raises(DriverConfigError) as err:
        backend.pin_factory("lgpio")
    assert "Read-only file system" in str(err.value) and "[pi] extra" not in str(err.value)
