"""The guided tensor set on the simulated appliance: the orientation asked for, redo, skip, abort, the stored set
linked to its releases, the tensor on Modbus and MQTT."""

from __future__ import annotations

import json

import numpy as np
import pytest
from pymodbus.client import ModbusTcpClient

from measurement import flags as F
from measurement import tensor as TS
from measurement.simulate import BRACKET
from service.commands.demo_tensor import TENSOR_RECIPE, recipe_text
from service.parts.recipes import RecipeError, load_recipe
from service.publish.modbus import registers as R
from tests.service.conftest import appliance_doc


def tensor_doc(tmp_path, **kwargs):
    recipes = tmp_path / "recipes"
    recipes.mkdir(exist_ok=True)
    (recipes / "bracket.toml").write_text(recipe_text(1), encoding="utf-8")
    return appliance_doc(tmp_path / "state", time_scale=25.0, recipes={"directory": str(recipes),
                                                                        "active": TENSOR_RECIPE},
                         simulation={"noise": 3e-4}, sequencer={"capture_duration": 10.0}, **kwargs)


def progress(app):
    return app.app.call_soon(app.app.set_progress).result(10)


def measure_step(app, n_done: int):
    """Mount the bracket as the set asks, press the button, wait for the result; returns the progress before."""
    p = progress(app)
    o = p["orientation"]
    cfg = app.app.config
    app.app.devices.sim.mount(BRACKET.mounted(cfg.rig, np.array(o["axis"]), o.get("offset"), cfg.simulation.effects))
    app.press()
    app.wait_done(n_done + 1)
    return p


def command(app, action):
    """An operator's set action, applied on the main loop before this returns."""
    app.app.command("set", "cli", {"action": action})
    app.app.call_soon(lambda: None).result(10)  # the command queue is drained before calls run


def modbus_read(app, start, count):
    c = ModbusTcpClient("127.0.0.1", port=app.app.modbus.bound_port, timeout=3, retries=0)
    assert c.connect()
    try:
        rr = c.read_input_registers(start, count=count, device_id=1)
        assert not rr.isError(), rr
        return R.decode_image(rr.registers, start=start)
    finally:
        c.close()


def test_a_guided_set_with_a_redo_and_a_skip_gives_a_stored_linked_tensor(tmp_path, appliance_factory):
    app = appliance_factory(tensor_doc(tmp_path))
    p = progress(app)
    assert p["status"] == "running" and p["step"] == 1 and p["steps"] == 6 and p["orientation"]["name"] == "x"
    assert "mount orientation 1 of 6 'x'" in p["instruction"]
    live = modbus_read(app, 0, R.SNAPSHOT_START)
    assert (live["set_step"], live["set_steps"], live["set_orientation"]) == (1, 6, 1)
    done = 0
    measure_step(app, done)
    done += 1
    assert progress(app)["orientation"]["name"] == "y"
    # redo: y has no release yet, so the previous orientation (x) is measured again
    command(app, "redo")
    assert progress(app)["orientation"]["name"] == "x"
    redone = measure_step(app, done)
    done += 1
    assert redone["orientation"]["name"] == "x"
    for _ in range(3):  # y, z, xy
        measure_step(app, done)
        done += 1
    assert progress(app)["orientation"]["name"] == "xz"
    measure_step(app, done)
    done += 1
    # yz skipped: the six left are five, which cannot determine the tensor, so the set fails, named
    command(app, "skip")
    p = progress(app)
    assert p["status"] == "failed" and "cannot determine" in p["error"] and p["skipped"] == ["yz"]
    [record] = app.app.store.tensor_sets(5)
    assert record["status"] == "failed" and record["tensor"] is None
    # every release stays stored and the set links the ones that counted (x's second release, not its first)
    stored = [m.uuid for m in app.app.store.list(limit=None)]  # newest first: xz, xy, z, y, x again, x
    assert len(stored) == done == 6
    links = record["releases"]
    assert links["x"] == [stored[4]] and stored[5] not in sum(links.values(), [])
    assert links["yz"] == [] and [links[n] for n in ("y", "z", "xy", "xz")] == [[stored[3]], [stored[2]],
                                                                                 [stored[1]], [stored[0]]]


def test_a_complete_set_publishes_its_tensor_on_modbus_and_mqtt(tmp_path, broker, appliance_factory,
                                                                 consumer_factory):
    c = consumer_factory(broker.port, ["moi/test-rig/#"])
    c.wait_subscribed()
    app = appliance_factory(tensor_doc(tmp_path, mqtt_port=broker.port))
    c.wait(lambda c: c.on("/status")[-1:] == [b"online"], 10, "online status")
    for i in range(6):
        measure_step(app, i)
    c.wait(lambda c: len(c.on("/tensor")) >= 1, 15, "the retained tensor")
    record = json.loads(c.on("/tensor")[-1])
    assert record["status"] == "complete" and record["recipe"] == TENSOR_RECIPE
    t = record["tensor"]
    z = (TS.entries_of(t["tensor"]) - TS.entries_of(BRACKET.tensor)) / np.sqrt(np.diag(t["tensor_cov"]))
    assert np.all(np.abs(z) < 4), z  # the simulated encoder is not the bench's: a loose check of the wiring
    assert json.loads(c.on("/set")[-1])["status"] == "complete"
    # every release payload says which orientation it counted for
    c.wait(lambda c: len(c.unique_results()) >= 6, 15, "the six results")
    names = [r["tensor_set"]["orientation"] for r in c.unique_results().values()]
    assert sorted(names) == sorted(["x", "y", "z", "xy", "xz", "yz"])
    block = modbus_read(app, R.TENSOR_START, R.TENSOR_END - R.TENSOR_START)
    assert block["tensor_seq"] == block["tensor_seq_end"] == 1
    for comp in TS.COMPONENTS:
        assert block[comp] == pytest.approx(t["components"][comp], rel=1e-6)
        assert block[f"{comp}_U"] == pytest.approx(t["tensor_U"][comp], rel=1e-6)
    assert block["I3"] == pytest.approx(t["principal_moments"][2], rel=1e-6)
    assert F.flags_from_bits(block["tensor_flags"] << 16) == [f for f in t["flags"] if f in F.FLAG_BITS]


def test_abort_keeps_the_measured_releases(tmp_path, appliance_factory):
    app = appliance_factory(tensor_doc(tmp_path))
    measure_step(app, 0)
    measure_step(app, 1)
    command(app, "abort")
    assert progress(app)["status"] == "aborted"
    [record] = app.app.store.tensor_sets(5)
    assert record["status"] == "aborted" and len(app.app.store.list(limit=None)) == 2
    assert record["releases"]["x"] and record["releases"]["y"] and not record["releases"]["z"]
    # the next trigger starts a new set
    app.press()
    app.wait_done(3)
    p = progress(app)
    assert p["status"] == "running" and p["uuid"] != record["uuid"] and p["orientation"]["name"] == "y"


def test_modbus_coils_act_on_the_set(tmp_path, appliance_factory):
    app = appliance_factory(tensor_doc(tmp_path))
    c = ModbusTcpClient("127.0.0.1", port=app.app.modbus.bound_port, timeout=3, retries=0)
    assert c.connect()
    try:
        assert not c.write_coil(R.COILS["set_skip"], True, device_id=1).isError()
    finally:
        c.close()
    app.app.call_soon(lambda: None).result(10)
    p = progress(app)
    assert p["skipped"] == ["x"] and p["orientation"]["name"] == "y"


def test_a_tensor_recipe_is_checked(tmp_path):
    good = tmp_path / "good.toml"
    good.write_text(recipe_text(2))
    r = load_recipe(good)
    assert r.tensor is not None and len(r.tensor.orientations) == 6 and r.spec is None and r.releases == 2
    bad = tmp_path / "bad.toml"
    bad.write_text(recipe_text(1).replace("[[tensor.orientation]]", "[[tensor.orientation]]\nspin = 1", 1))
    with pytest.raises(RecipeError, match=r"\[tensor\].*unknown key"):
        load_recipe(bad)
    bad.write_text(recipe_text(1).replace("releases = 1", "releases = 1\nnominal = 0.01"))
    with pytest.raises(RecipeError, match="do not apply"):
        load_recipe(bad)
    assert F.ORIENTATION_EXCLUDED in F.FLAG_BITS


def test_the_web_page_shows_the_orientation_to_mount_and_takes_the_actions(tmp_path, appliance_factory):
    import urllib.request
    from pathlib import Path

    app = appliance_factory(tensor_doc(tmp_path, web={"enabled": True}))
    base = app.app.web.url
    html = urllib.request.urlopen(base + "set", timeout=10).read().decode()
    assert "mount orientation 1 of 6 &#39;x&#39;" in html or "mount orientation 1 of 6 'x'" in html
    assert "<svg" in html and "swing axis" in html and 'id="measure"' in html  # measured from the set's page
    # Home, the operator's screen, says which orientation to mount, with its drawing
    home = urllib.request.urlopen(base, timeout=10).read().decode()
    assert 'TENSOR SET' in home and 'id="set-orientation">x<' in home and 'id="set-drawing"' in home
    token = Path(app.app.web.token_file).read_text().strip()
    req = urllib.request.Request(base + "api/set/skip", data=b"", method="POST",
                                 headers={"Authorization": f"Bearer {token}", "Origin": base.rstrip("/")})
    assert urllib.request.urlopen(req, timeout=10).status == 202
    app.app.call_soon(lambda: None).result(10)
    state = json.loads(urllib.request.urlopen(base + "api/set", timeout=10).read())
    assert state["set"]["skipped"] == ["x"] and state["set"]["orientation"]["name"] == "y"


def test_moi_demo_tensor_runs_a_whole_set_and_prints_the_error_against_the_truth():
    import subprocess
    import sys
    from pathlib import Path

    r = subprocess.run([sys.executable, "-m", "service.cli", "demo", "--tensor"], capture_output=True, text=True,
                       timeout=300, cwd=Path(__file__).resolve().parents[3])
    assert r.returncode == 0, r.stderr
    assert r.stdout.count("mount orientation") == 6 and "complete, stored with its 6 releases" in r.stdout
    rows = [line.split() for line in r.stdout.splitlines() if line.split()[:1] and line.split()[0] in TS.COMPONENTS]
    assert len(rows) == 6 and all(abs(float(row[-1])) < 4 for row in rows), rows  # error/σ per component
    assert "Modbus tensor block 200–238" in r.stdout
