"""`moi demo --tensor`: a guided six-orientation tensor set on the simulated appliance, end to end.

The real daemon (``service.daemon.Appliance``) runs with a temporary store and
a tensor recipe (the example bracket, ``measurement.simulate.BRACKET``, in the
usual six orientations, its centre of mass off the swing axis in two of them).
This command plays the operator: it reads which orientation the daemon asks
for, mounts the simulated part that way on the simulated rig, presses the
push button, and at the end prints the stored tensor, its error against the
truth, and the Modbus tensor block read back over TCP.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from pathlib import Path

import numpy as np

EXIT_FAULT = 3
TENSOR_RECIPE = "bracket-tensor"
#: the centre of mass off the swing axis in two orientations of the demo set (m, part frame)
DEMO_OFFSETS = {"x": (0.0, 0.03, -0.02), "xz": (0.01, 0.025, 0.0)}
DEMO_OFFSET_STD = 2e-5   # m
DEMO_MASS_STD = 1e-4     # kg


def recipe_text(releases: int) -> str:
    """The demo's tensor recipe: the example bracket, the usual six orientations."""
    from measurement.simulate import BRACKET
    from measurement.tensor import DEFAULT_AXES

    lines = ["# the tensor recipe of `moi demo --tensor`: the example bracket in the usual six orientations",
             f'[recipe]\nname = "{TENSOR_RECIPE}"\nnumber = 40\nreleases = {releases}\n',
             f'[tensor.part]\nname = "bracket"\nmass = {BRACKET.mass!r}\nmass_std = {DEMO_MASS_STD!r}\n'
             'poi_convention = "negative"\n']
    for name, axis in DEFAULT_AXES:
        lines.append(f'[[tensor.orientation]]\nname = "{name}"\naxis = [{", ".join(repr(v) for v in axis)}]')
        if name in DEMO_OFFSETS:
            lines.append(f"offset = [{', '.join(repr(v) for v in DEMO_OFFSETS[name])}]\noffset_std = {DEMO_OFFSET_STD!r}")
        lines.append("")
    return "\n".join(lines)


def run_in(args: argparse.Namespace, state_dir: str) -> int:
    """The demo with its store and recipe in ``state_dir`` (`moi demo` checked the arguments)."""
    from service.config.appliance import parse_config
    from service.daemon import Appliance

    recipes = Path(state_dir) / "recipes"
    recipes.mkdir(parents=True, exist_ok=True)
    (recipes / f"{TENSOR_RECIPE}.toml").write_text(recipe_text(args.releases), encoding="utf-8")
    doc = {
        "device": {"id": "demo", "state_dir": state_dir, "log_level": "warning"},
        "sequencer": {"pre_trigger": 0.2, "capture_duration": args.duration, "sample_timeout": 2.0},
        # the in-process sensor: six orientations in seconds, not minutes
        "simulation": {"time_scale": 10.0, "rate": 100.0, "seed": args.seed, "sensor": "direct",
                       "noise": 3e-4, "effects": {"viscous": {"c": 1.5e-4}}},
        "modbus": {"host": "127.0.0.1", "port": 0},
        "web": {"host": "127.0.0.1", "port": 0, "enabled": False},
        "recipes": {"directory": str(recipes), "active": TENSOR_RECIPE},
    }
    config = parse_config(doc, source="moi demo --tensor")
    return _run(Appliance(config, stop_grace=5.0), args)


class _Releases:
    """Collects the measurements the sequencer publishes; ``done`` is set when one ends."""

    def __init__(self, app) -> None:
        self.done = threading.Event()
        self.published: list = []
        app.sequencer.subscribe(self.on_event)

    def on_event(self, e) -> None:
        if e.publishes:
            self.published.append(e.measurement)
        if e.ends_measurement:
            self.done.set()


def _run(app, args: argparse.Namespace) -> int:
    app.start()
    releases = _Releases(app)
    main = threading.Thread(target=app.run, name="moi-demo-main", daemon=True)
    main.start()
    t0 = time.monotonic()
    try:
        _print_setup(app)
        if not _measure_orientations(app, releases, t0):
            return EXIT_FAULT
        sets = app.call_soon(lambda: app.store.tensor_sets(1)).result(10)
        if not sets or sets[0]["status"] != "complete":
            why = sets[0].get("error") if sets else "no set stored"
            print(f"moi demo: the tensor set did not complete: {why}", file=sys.stderr)
            return EXIT_FAULT
        record = sets[0]
        print(f"[{time.monotonic() - t0:6.2f} s] tensor set {record['uuid']} complete, stored with its "
              f"{sum(len(v) for v in record['releases'].values())} releases")
        print()
        _print_tensor(record["tensor"])
        _print_registers(app)
        if args.json:
            print(json.dumps(record, ensure_ascii=False))
        return 0
    finally:
        app.request_stop()
        main.join(30)


def _print_setup(app) -> None:
    """The recipe, the true part and where the Modbus server is."""
    from measurement.simulate import BRACKET

    cfg, recipe = app.config, app.parts.recipe
    print(f"tensor recipe {recipe.name}: {len(recipe.tensor.orientations)} orientations, {recipe.releases} "
          f"release(s) each, on the simulated {cfg.rig.kind} rig (tare {cfg.rig.tare_inertia:g} kg·m²)")
    print(f"the true part: the example bracket, {BRACKET.mass:g} kg, tensor about its centre of mass (kg·m²) "
          f"{np.array(BRACKET.tensor).tolist()}")
    print(f"Modbus TCP server on 127.0.0.1:{app.modbus.bound_port}")


def _measure_orientations(app, releases: _Releases, t0: float) -> bool:
    """Play the operator until the set stops running: mount the bracket as the daemon asks, press the push
    button's mock pin, print each release. False (said on stderr) when a release brings no result."""
    from measurement.simulate import BRACKET

    cfg = app.config
    limit = 60.0 + (cfg.sequencer.pre_trigger + cfg.sequencer.capture_duration) / cfg.simulation.time_scale
    while True:
        progress = app.call_soon(app.set_progress).result(10)
        if progress is None or progress["status"] != "running":
            return True
        o = progress["orientation"]
        print(f"[{time.monotonic() - t0:6.2f} s] {progress['instruction']}")
        # the operator mounts the part as asked: on the simulated rig, the bracket about that axis
        app.devices.sim.mount(BRACKET.mounted(cfg.rig, np.array(o["axis"]), o.get("offset"),
                                              cfg.simulation.effects))
        releases.done.clear()
        n = len(releases.published)
        pin = app.devices.button.pin
        pin.drive_low()
        pin.drive_high()
        if not releases.done.wait(limit):
            print(f"moi demo: no result within {limit:.0f} s", file=sys.stderr)
            return False
        if len(releases.published) <= n:
            print(f"moi demo: the measurement failed: {app.sequencer.last_fault}", file=sys.stderr)
            return False
        r = releases.published[-1].result
        print(f"          released: J_object = {r.J_object:.7g} ± {r.J_object_std:.2g} kg·m² about the swing axis"
              f" (true {app.devices.sim.inertia - (cfg.rig.tare_inertia or 0.0):.7g})")


def _print_tensor(t: dict) -> None:
    """The stored tensor (``TensorResult.to_dict()``) against the bracket's: components, principal moments
    and axes."""
    from measurement import tensor as TS
    from measurement.simulate import BRACKET

    truth = TS.entries_of(BRACKET.tensor)
    est = TS.entries_of(t["tensor"])
    sigma = np.sqrt(np.diag(t["tensor_cov"]))
    print(f"{'':6}{'measured':>16}{'U (k=2)':>11}{'true':>14}{'error':>13}{'error/σ':>9}")
    for c, e, s, tr in zip(TS.COMPONENTS, est, sigma, truth):
        print(f"{c:6}{e:>16.8g}{2 * s:>11.2g}{tr:>14.8g}{e - tr:>+13.2e}{(e - tr) / s:>+9.2f}")
    lam_true, vec_true = np.linalg.eigh(np.array(BRACKET.tensor))
    for k in range(3):
        axis = np.array(t["principal_axes"][k])
        angle = np.degrees(np.arccos(min(1.0, abs(float(axis @ vec_true[:, k])))))
        print(f"I{k + 1} = {t['principal_moments'][k]:.8g} ± {t['principal_moments_U'][k]:.2g} kg·m² (true "
              f"{lam_true[k]:.8g}); axis {np.round(axis, 4).tolist()} off the true axis by {angle:.3f}° "
              f"(stated ± {t['principal_axes_U_deg'][k]:.2g}°)")
    print(f"flags: {', '.join(t['flags']) or 'none'}")


def _print_registers(app) -> None:
    """The Modbus tensor block and the set's live registers, read back over TCP with a real client."""
    from pymodbus.client import ModbusTcpClient

    from measurement import tensor as TS
    from service.publish.modbus import registers as R

    unit = app.config.modbus.unit_id
    client = ModbusTcpClient("127.0.0.1", port=app.modbus.bound_port, timeout=3)
    client.connect()
    try:
        rr = client.read_input_registers(R.TENSOR_START, count=R.TENSOR_END - R.TENSOR_START, device_id=unit)
        live = client.read_input_registers(0, count=R.SNAPSHOT_START, device_id=unit)
    finally:
        client.close()
    block = R.decode_image(rr.registers, start=R.TENSOR_START)
    regs = R.decode_image(live.registers)
    print()
    print(f"Modbus tensor block {R.TENSOR_START}–{R.TENSOR_END - 1} read back over TCP (tensor_seq "
          f"{block['tensor_seq']}): " + ", ".join(f"{c} {block[c]:.7g}" for c in TS.COMPONENTS)
          + f"; I1…I3 {block['I1']:.7g}, {block['I2']:.7g}, {block['I3']:.7g}; flags 0x{block['tensor_flags']:04x}")
    print(f"live registers: set_step {regs['set_step']}, set_steps {regs['set_steps']}, "
          f"set_orientation {regs['set_orientation']} (the set is done)")
