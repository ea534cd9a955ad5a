"""Recipes, part IDs and verdicts on the simulated appliance, driven by a real pymodbus client (the PLC)
and a real Mosquitto; recipe files checked with one-line errors."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from pymodbus.client import ModbusTcpClient

from measurement import flags as F
from measurement.verdict import Specification, decide
from service.errors import ConfigError
from service.parts.recipes import RecipeBook, RecipeError, load_recipe
from service.publish.modbus import registers as R
from service.publish.replies import REASONS
from tests.judged import judged
from tests.service.conftest import appliance_doc, wait_until
from tests.service.publish.modbus.test_service_plc_handshake import bit, image
from tests.service.publish.modbus.test_service_plc_handshake import write as write_register

J_TRUE = 0.0125  # the simulated part (appliance_doc's default [simulation] inertia)


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def recipe(name: str, number: int, nominal: float, extra: str = "", **keys) -> str:
    lines = [f'name = "{name}"', f"number = {number}", f"nominal = {nominal!r}"]
    lines += [f"{k} = {json.dumps(v)}" for k, v in keys.items()]
    return "[recipe]\n" + "\n".join(lines) + "\n" + extra


CAL_RIG = """[rig]
kind = "torsion"
stiffness = 0.3651
stiffness_std = 0.0018      # 0.5 % of k: U of J is about 1 %
tare_inertia = 4.5043e-3
[model]
declared = ["viscous"]
[calibration]
date = 2020-01-15
valid_days = 365            # long expired
"""


@pytest.fixture
def recipe_dir(tmp_path) -> Path:
    d = tmp_path / "recipes"
    write(d / "ok.toml", recipe("rotor-ok", 7, J_TRUE, tolerance_percent=1.0, releases=3))
    write(d / "big.toml", recipe("rotor-big", 8, 0.0130, tolerance_percent=1.0, releases=1))
    write(tmp_path / "rigs" / "cal-rig.toml", CAL_RIG)
    # nominal 0.5 % above the part, tolerance 0.8 %: the plain comparison says OK, U ≈ 1 % (k's uncertainty) does not
    write(d / "guard.toml", recipe("rotor-guard", 9, J_TRUE * 1.005, tolerance_percent=0.8, releases=1,
                                   rig="../rigs/cal-rig.toml")
          + '[quality]\ninvalid_flags = ["unmodeled_residual"]\n')
    write(d / "caldue.toml", recipe("rotor-caldue", 10, J_TRUE, tolerance_percent=5.0, releases=1,
                                    rig="../rigs/cal-rig.toml"))
    write(d / "strict.toml", recipe("rotor-strict", 11, J_TRUE, tolerance_percent=1.0, releases=1)
          + "[quality]\nmax_J_std = 1e-12\n")
    # a check standard whose certificate is 1 % off the artifact: E_n > 1, the station's calibration is due
    write(d / "check.toml", recipe("check-disc", 12, J_TRUE, tolerance_percent=5.0, releases=1)
          + f"[check_standard]\nreference = {J_TRUE * 1.01!r}\nreference_U = 2e-5\nname = \"disc CS-1\"\n")
    write(d / "after.toml", recipe("rotor-after", 13, J_TRUE, tolerance_percent=5.0, releases=1))
    # information flags invalidate nothing by default; a recipe may still name one
    write(d / "rub.toml", recipe("rotor-rub", 14, 0.0130, tolerance_percent=1.0, releases=1)
          + '[quality]\ninvalid_flags = ["unmodeled_residual"]\n')
    return d


def refused_trigger(c: ModbusTcpClient) -> dict:
    """A trigger through the command register while the calibration blocks: the registers once it is answered
    (refused, nothing started)."""
    v = wait_until(lambda: (v := image(c)) and not bit(v, "ready") and bit(v, "calibration_due") and v, 10,
                   what="not ready, calibration due")
    count = v["command_count"]
    assert not write_register(c, "command", R.COMMAND_CODES["trigger"], 0).isError()
    v = wait_until(lambda: (v := image(c))["command_count"] > count and v, 10, what="the trigger answered")
    assert v["command_status"] == R.COMMAND_STATUS["refused"] and not bit(v, "trigger_ack")
    assert not write_register(c, "command", 0).isError()
    return v


def plc(app) -> ModbusTcpClient:
    c = ModbusTcpClient("127.0.0.1", port=app.app.modbus.bound_port, timeout=3, retries=0)
    assert c.connect()
    return c


def snapshot(c: ModbusTcpClient) -> dict:
    snap = R.read_snapshot(lambda a, n: c.read_input_registers(a, count=n, device_id=1).registers)
    assert snap is not None, "no consistent snapshot"
    return snap


def select(c: ModbusTcpClient, number: int) -> None:
    assert not c.write_register(R.WRITABLE["recipe_select"][0], number, device_id=1).isError()


def write_part_id(c: ModbusTcpClient, text: str):
    return c.write_registers(R.WRITABLE["part_id"][0], R.encode_ascii(text, R.PART_ID_CHARS), device_id=1)


def test_a_plc_selects_a_recipe_writes_a_part_id_and_reads_the_verdict_of_three_releases(tmp_path, recipe_dir,
                                                                                      appliance_factory):
    app = appliance_factory(appliance_doc(tmp_path / "state", time_scale=10.0, recipes={"directory": str(recipe_dir)}))
    c = plc(app)
    try:
        select(c, 7)
        assert not write_part_id(c, "SN-0001").isError()
        back = c.read_holding_registers(R.WRITABLE_START, count=R.WRITABLE_END - R.WRITABLE_START, device_id=1)
        assert R.decode_ascii(back.registers[:10]) == "SN-0001" and back.registers[10] == 7
        for i in range(1, 4):
            assert not c.write_coil(R.COILS["trigger"], True, device_id=1).isError()
            if i == 2:  # the part cannot change while it is measured: server device busy
                app.wait_event(lambda e: e.state.value == "CAPTURING", 20, count=2)
                rr = write_part_id(c, "SN-9999")
                assert rr.isError() and rr.exception_code == 0x06
            app.wait_done(i)
            s = snapshot(c)
            assert s["release_index"] == i and s["releases"] == 3 and s["part_id"] == "SN-0001"
            assert s["recipe_number"] == 7 and s["release_verdict"] == R.VERDICT_CODES["OK"], \
                app.app.store.get(s["uuid"]).payload["release"]
            if i < 3:
                assert s["verdict"] == 0 and math.isnan(s["part_value"])  # the part is not complete yet
                assert R.decode_image(c.read_input_registers(0, count=10, device_id=1).registers)["part_releases_done"] == i
        assert s["verdict"] == R.VERDICT_CODES["OK"]
        # U of the part: the demo rig's calibration (k known to 0.09 %) dominates, the releases average down
        assert abs(s["part_value"] / J_TRUE - 1) < 2e-3 and 1e-5 < s["part_U"] < 5e-5
        live = R.decode_image(c.read_input_registers(0, count=10, device_id=1).registers)
        assert live["status"] & (1 << R.STATUS_BITS["part_ok"]) and not live["status"] & (1 << R.STATUS_BITS["part_nok"])
        assert live["recipe"] == 7 and live["part_releases_done"] == 0
        di = c.read_discrete_inputs(0, count=len(R.STATUS_BITS), device_id=1).bits
        assert di[R.STATUS_BITS["part_ok"]] and not di[R.STATUS_BITS["part_invalid"]]
    finally:
        c.close()
    rows = app.app.store.list(part_id="SN-0001", full=True)
    assert [m.release_index for m in reversed(rows)] == [1, 2, 3]
    assert {m.part_uuid for m in rows} == {rows[0].part_uuid} and rows[0].part_verdict == "OK"
    last = rows[0].payload
    assert last["part"]["measurements"] == [m.uuid for m in reversed(rows)]
    assert last["part"]["used"] == [0, 1, 2] and last["part"]["excluded"] == []
    assert last["part"]["u_typeA"] == pytest.approx(last["part"]["std"] / math.sqrt(3))
    # the part's value is the three releases identified jointly, and they agree with it
    joint = last["part"]["joint"]
    assert joint["consistency"]["dof"] == 2 and joint["consistency"]["p"] >= 0.01
    assert "viscous" in joint["effects"] and last["part"]["mean"] == pytest.approx(J_TRUE, rel=2e-3)
    assert last["recipe"]["version"] == rows[0].recipe_version == load_recipe(recipe_dir / "ok.toml").version
    assert all(m.payload["part_id"] == "SN-0001" for m in rows)


def test_nok_guard_band_calibration_due_and_invalid_each_reached(tmp_path, recipe_dir, appliance_factory):
    app = appliance_factory(appliance_doc(tmp_path / "state", time_scale=10.0, recipes={"directory": str(recipe_dir)}))
    c = plc(app)
    verdicts, refused = {}, {}
    try:
        # outside the refused block: the result image and the gap before the part ID block
        for address in (R.SNAPSHOT_START, R.WRITABLE_START - 1, R.WRITABLE_END):
            rr = c.write_register(address, 1, device_id=1)
            assert rr.isError() and rr.exception_code == 0x02, address
        rr = c.write_register(R.WRITABLE["recipe_select"][0], 99, device_id=1)  # no such recipe
        assert rr.isError() and rr.exception_code == 0x03
        n = 0
        for number in (8, 9, 10, 11, 12, 13):
            select(c, number)
            assert not write_part_id(c, f"P-{number}").isError()
            if number in (10, 13):  # a part every result of which would be INVALID: refused before it starts
                refused[number] = refused_trigger(c)
                continue
            assert not c.write_coil(R.COILS["trigger"], True, device_id=1).isError()
            n += 1
            app.wait_done(n)
            s = snapshot(c)
            payload = app.app.store.get(s["uuid"]).payload
            assert s["part_id"] == payload["part_id"] == f"P-{number}"
            verdicts[number] = (s["verdict"], payload)
    finally:
        c.close()
    assert app.app.store.count() == 4
    code = R.VERDICT_CODES
    verdict, p = verdicts[8]
    assert verdict == code["NOK"] and p["part"]["zone"] == "nonconformance", (p["flags"], p["part"])
    # the guard band: inside the tolerance, so the plain comparison says OK; with U it is not proven
    verdict, p = verdicts[9]
    part = p["part"]
    spec = p["recipe"]
    assert verdict == code["NOK"] and part["zone"] == "uncertainty", (p["flags"], p["part"])
    assert abs(part["mean"] - spec["nominal"]) <= spec["upper"] - spec["nominal"]
    assert decide(part["mean"], part["u_c"], Specification("J", spec["nominal"], spec["lower"], spec["upper"],
                                                           rule="simple")).verdict == "OK"
    assert part["U"] == pytest.approx(2 * math.hypot(p["uncertainty_budget"]["J"]["u_systematic"], max(part["u_fit"], 0)), rel=1e-6)
    # the expired calibration: flagged in the payload and the Modbus flags; this recipe ignores it
    assert "calibration_due" in p["flags"] and p["calibration"]["due"] is True
    assert p["flag_bits"] & (1 << F.FLAG_BITS["calibration_due"])
    # ... the next one, whose quality rules make a due calibration INVALID, is refused at the trigger: measuring
    # again could not change its verdict (the PLC reads why: not ready, reason calibration_due)
    assert refused[10]["command_reason"] == REASONS["calibration_due"].code
    verdict, p = verdicts[11]
    assert verdict == code["INVALID"] and "above the limit" in p["part"]["excluded"][0]["reason"], (p["flags"], p["part"])
    # the check standard measured at the station: E_n stored with the history; the next part is INVALID
    verdict, p = verdicts[12]
    check = p["part"]["check_standard"]
    assert check["name"] == "disc CS-1" and check["E_n"] > 1 and not check["passed"]
    assert app.app.store.check_standards(limit=1)[0]["E_n"] == check["E_n"]
    assert refused[13]["command_reason"] == REASONS["calibration_due"].code
    assert app.app.measure_block()["calibration"]["check_standard"]["passed"] is False
    # the check standard is not refused for the calibration_due its own failure raised: a passing one clears it
    assert "calibration_due" not in load_recipe(recipe_dir / "check.toml").quality.invalid_flags


@pytest.mark.broker
def test_mqtt_selects_the_recipe_and_the_measure_command_carries_the_part_id(tmp_path, recipe_dir, broker,
                                                                            appliance_factory, consumer_factory):
    c = consumer_factory(broker.port, ["moi/test-rig/#"])
    c.wait_subscribed()
    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=broker.port, time_scale=10.0,
                                          recipes={"directory": str(recipe_dir), "active": "rotor-ok"}))
    assert app.app.mqtt.connected_event.wait(10)
    # the daemon subscribes right after it connected: repeat the (idempotent) selection until it is seen
    for _ in range(50):
        c.publish("moi/test-rig/cmd/recipe", "rotor-big")
        try:
            wait_until(lambda: app.app.modbus.inputs()["recipe_select"] == 8, 0.2, what="recipe 8 selected")
            break
        except AssertionError:
            continue
    assert app.app.parts.recipe.name == "rotor-big"
    c.publish("moi/test-rig/cmd/measure", json.dumps({"id": "m-1", "part_id": "MQ-42"}))
    c.wait(lambda c: len(c.results()) >= 1, 30, "a result")
    [msg] = c.results()
    assert msg["part_id"] == "MQ-42" and msg["recipe"]["name"] == "rotor-big" and msg["verdict"] == "NOK"
    assert msg["release"] == {**msg["release"], "index": 1, "of": 1, "verdict": "NOK"}
    assert app.app.modbus.inputs() == {"part_id": "MQ-42", "recipe_select": 8}
    # after each part the recipe's SPC summary is retained on spc/<recipe>
    c.wait(lambda c: len(c.on("/spc/rotor-big")) >= 1, 10, "the SPC summary after the first part")
    assert json.loads(c.on("/spc/rotor-big")[-1])["status"] == "fewer than 2 usable parts"
    app.wait_done(1)  # a command while the first one is still PUBLISHING is refused, like the button
    c.publish("moi/test-rig/cmd/measure", json.dumps({"id": "m-2", "part_id": "MQ-43"}))
    c.wait(lambda c: len(c.on("/spc/rotor-big")) >= 2, 30, "the SPC summary after the second part")
    spc = json.loads(c.on("/spc/rotor-big")[-1])
    c.wait(lambda c: len(c.unique_results()) >= 2, 30, "the second result")
    values = [r["part"]["mean"] for r in c.unique_results().values()]
    assert spc["status"] == "ok" and spc["chart"] == "I-MR" and spc["parts"] == 2
    assert spc["mean"] == pytest.approx(sum(values) / 2) and spc["range_mean"] == pytest.approx(abs(values[1] - values[0]))
    late = consumer_factory(broker.port, ["moi/test-rig/spc/#"], client_id="late-reader")
    late.wait(lambda c: len(c.on("/spc/rotor-big")) == 1, 10, "the retained SPC summary")
    assert late.messages[0][2] is True  # delivered as retained


def test_recipe_files_are_checked_with_one_line_errors(tmp_path):
    cases = {
        "no-tolerance": (recipe("a", 1, 0.01), "give exactly one of tolerance"),
        "bad-number": (recipe("a", 0, 0.01, tolerance=1e-4), "[recipe] number: expected an integer in [1, 65535]"),
        "unknown-key": (recipe("a", 1, 0.01, tolerance=1e-4, tolerence=1), "[recipe]: unknown key 'tolerence' (did you mean 'tolerance'?)"),
        "negative": (recipe("a", 1, 0.01, tolerance=-1e-4), "[recipe] tolerance: expected a number > 0, got -0.0001"),
        "rule": (recipe("a", 1, 0.01, tolerance=1e-4) + '[decision]\nrule = "lenient"\n', "[decision] rule: expected one of"),
        "effect": (recipe("a", 1, 0.01, tolerance=1e-4, declared=["magic"]), "unknown effect 'magic'"),
        "quantity": (recipe("a", 1, 0.01, tolerance=1e-4, quantity="mass"), "[recipe] quantity: expected one of"),
        "min-valid": (recipe("a", 1, 0.01, tolerance=1e-4, releases=2) + "[quality]\nmin_valid_releases = 3\n",
                      "at most releases = 2"),
        "tur": (recipe("a", 1, 0.01, tolerance=1e-4) + "[quality]\nmax_uncertainty_ratio = -0.25\n",
                "[quality] max_uncertainty_ratio: expected a number > 0"),
        "check-u": (recipe("a", 1, 0.01, tolerance=1e-4) + "[check_standard]\nreference = 0.01\n",
                    "[check_standard] reference_U"),
        "check-neg": (recipe("a", 1, 0.01, tolerance=1e-4) + '[check_standard]\nreference_U = "2e-5"\n',
                      "[check_standard] reference_U: expected a number > 0"),
        "check-name": (recipe("a", 1, 0.01, tolerance=1e-4)
                       + '[check_standard]\nreference_U = 2e-5\nname = "disc \\u001b[2J"\n',
                       "[check_standard] name: check standard name must be printable characters"),
    }
    for name, (text, message) in cases.items():
        path = write(tmp_path / f"{name}.toml", text)
        with pytest.raises(RecipeError) as err:
            load_recipe(path)
        assert str(err.value).startswith(str(path)) and message in str(err.value) and "\n" not in str(err.value), name
    d = tmp_path / "dup"
    write(d / "a.toml", recipe("a", 1, 0.01, tolerance=1e-4))
    write(d / "b.toml", recipe("b", 1, 0.01, tolerance=1e-4))
    with pytest.raises(RecipeError, match="number: 1 is already used by"):
        RecipeBook.load(d)
    assert isinstance(RecipeError("x"), ConfigError)
    # the quantity must be one the rig can give: J_object needs a tare
    from measurement import Rig
    r = load_recipe(write(tmp_path / "obj.toml", recipe("o", 5, 0.01, tolerance=1e-4, quantity="J_object")))
    with pytest.raises(RecipeError, match=r"obj.toml: \[recipe\] quantity: J_object needs the rig's tare_inertia"):
        r.check_rig(Rig(kind="torsion", stiffness=0.3651))
    r.check_rig(Rig(kind="torsion", stiffness=0.3651, tare_inertia=4.5e-3))
    with pytest.raises(RecipeError, match="the rig gives no J"):
        r.check_rig(Rig(kind="torsion"))


def test_moi_run_check_validates_every_recipe(tmp_path, capsys):
    from service.cli import main

    d = tmp_path / "recipes"
    write(d / "good.toml", recipe("good", 1, 0.01, tolerance=1e-4))
    bad = write(d / "bad.toml", recipe("bad", 2, 0.01, tolerance_percent=0))
    cfg = write(tmp_path / "appliance.toml", '[recipes]\ndirectory = "recipes"\nactive = "good"\n')
    assert main(["run", "--check", "--config", str(cfg)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and str(bad) in lines[0] and "tolerance_percent: expected a number > 0" in lines[0]
    bad.unlink()
    assert main(["run", "--check", "--json", "--config", str(cfg)]) == 0
    assert json.loads(capsys.readouterr().out)["recipes"]["recipes"][0]["name"] == "good"
    write(tmp_path / "appliance.toml", '[recipes]\ndirectory = "recipes"\nactive = "nope"\n')
    assert main(["run", "--check", "--config", str(cfg)]) == 2
    err = capsys.readouterr().err
    assert "[recipes] active: " in err and "no recipe 'nope'" in err


def test_the_part_tracker_counts_releases_reports_an_abandoned_part_and_forgets_an_unstored_release(tmp_path):
    from service.parts.outcome import PartOutcome
    from service.parts.tracker import PartTracker

    d = tmp_path / "recipes"
    write(d / "r.toml", recipe("r", 1, J_TRUE, tolerance_percent=1.0, releases=2))
    tracker = PartTracker(RecipeBook.load(d), "r")
    result = judged({"J": J_TRUE}, 1e-7, omega_n=5.4, window={"t_start": 0.0, "t_stop": 10.0})
    r = tracker.recipe
    first = tracker.release(result, "m1", "A", r)
    assert first.release is not None and first.release.index == 1 and first.verdict is None and (tracker.open_part or {}).get("done") == 1
    tracker.undo_last()  # m1 could not be stored
    assert tracker.open_part is None
    tracker.release(result, "m1b", "A", r)
    other = tracker.release(result, "m2", "B", r)  # a new part ID before A was complete
    assert other.release is not None
    abandoned = other.release.abandoned
    assert abandoned is not None
    assert abandoned["part_id"] == "A" and abandoned["done"] == 1 and abandoned["of"] == 2
    assert abandoned["part_uuid"] != other.release.part_uuid and "different part ID" in abandoned["reason"]
    done = tracker.release(result, "m3", "B", r)
    assert done.verdict == "OK" and done.part is not None and done.part.measurements == ("m2", "m3")
    # the dict form is the payload's: the part's value under both of its wire names
    wire = done.to_dict()["part"]
    assert wire["mean"] == wire["value"] == done.part.value and PartOutcome.from_dict(done.to_dict()) == done
    with pytest.raises(RecipeError, match="no recipe 'x'"):
        tracker.select("x")


def test_a_release_under_a_tensor_recipe_is_not_judged_and_ends_the_open_part(tmp_path):
    # a tensor recipe has no single quantity (spec None): its release outside a set gets no verdict
    from service.commands.demo_tensor import recipe_text
    from service.parts.tracker import PartTracker

    d = tmp_path / "recipes"
    write(d / "r.toml", recipe("r", 1, J_TRUE, tolerance_percent=1.0, releases=2))
    write(d / "t.toml", recipe_text(1))
    book = RecipeBook.load(d)
    tracker = PartTracker(book, "r")
    result = judged({"J": J_TRUE}, 1e-7, omega_n=5.4, window={"t_start": 0.0, "t_stop": 10.0})
    tracker.release(result, "m1", "A", tracker.recipe)
    assert (tracker.open_part or {}).get("done") == 1
    tensor = next(r for r in book.recipes if r.spec is None)
    out = tracker.release(result, "m2", "A", tensor)
    assert out.release is None and out.part is None and out.verdict is None
    assert (out.recipe or {})["name"] == tensor.name and tracker.open_part is None


def test_a_recipe_that_names_an_information_flag_invalidates_by_it(tmp_path, recipe_dir, appliance_factory):
    # the part rubs (Coulomb friction) but the model may not learn it: the residual keeps the structure
    doc = appliance_doc(tmp_path / "state", time_scale=10.0,
                        recipes={"directory": str(recipe_dir), "active": "rotor-rub"},
                        identification={"discover": False},
                        simulation={"effects": {"viscous": {"c": 1.5e-4}, "coulomb": {"Tc": 4e-4}}})
    app = appliance_factory(doc)
    app.app.command("part_id", "test", {"part_id": "RUB-1"})
    app.press()
    app.wait_done(1)
    [row] = app.app.store.list(full=True)
    p = row.payload
    assert "unmodeled_residual" in p["flags"] and row.part_id == "RUB-1"
    assert p["verdict"] == row.part_verdict == "INVALID" and p["release"]["reasons"] == ["flag unmodeled_residual"]


def test_a_part_needs_all_its_releases_unless_the_recipe_says_otherwise(tmp_path):
    from measurement.verdict import Reading, combine

    two = load_recipe(write(tmp_path / "two.toml", recipe("two", 1, J_TRUE, tolerance_percent=1.0, releases=2)))
    assert two.quality.min_valid_releases == 2 and two.spec is not None
    good = Reading(J_TRUE, 1e-7)
    bad = Reading(J_TRUE, 1e-7, flags=("fit_not_converged",))
    part = combine([good, bad], two.spec, two.quality)
    assert part.verdict == "INVALID" and part.excluded[0]["index"] == 1  # one INVALID release: no pass, said
    lenient = load_recipe(write(tmp_path / "one.toml", recipe("one", 2, J_TRUE, tolerance_percent=1.0, releases=2)
                                + "[quality]\nmin_valid_releases = 1\n"))
    assert lenient.spec is not None
    assert combine([good, bad], lenient.spec, lenient.quality).verdict == "OK"
    with pytest.raises(RecipeError, match="display_unit: unknown unit of inertia 'cubits'"):
        load_recipe(write(tmp_path / "u.toml", recipe("u", 3, J_TRUE, tolerance_percent=1.0, display_unit="cubits")))
    assert load_recipe(write(tmp_path / "g.toml", recipe("g", 4, J_TRUE, tolerance_percent=1.0,
                                                         display_unit="g*cm^2"))).to_dict()["display_unit"] == "g·cm²"


def test_a_recipe_edit_keeps_the_file_s_comments_and_a_refused_one_leaves_it_as_it_was(tmp_path):
    from service.parts.recipes import edit_recipe

    f = tmp_path / "a.toml"
    f.write_text('# rotor A, drawing 4711\n[recipe]\nname = "rotor-a"\nnumber = 3\nnominal = 0.0125  # kg·m²\n'
                 'tolerance = 0.0002\n')
    new, changes = edit_recipe(load_recipe(f), {"nominal": "0.013", "tolerance": "0.0002", "display_decimals": "6"})
    assert changes == {"nominal": (0.0125, 0.013), "display_decimals": (None, 6)}
    assert new.spec is not None and new.spec.nominal == 0.013 and new.display_decimals == 6
    text = f.read_text()
    assert "# rotor A, drawing 4711" in text and "nominal = 0.013  # kg·m²" in text
    with pytest.raises(RecipeError, match=r"a\.toml: \[recipe\] tolerance: expected less than the nominal"):
        edit_recipe(new, {"tolerance": "0.5"})
    assert f.read_text() == text and sorted(p.name for p in tmp_path.iterdir()) == ["a.toml"]  # no trial file left
