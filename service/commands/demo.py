"""`moi demo` (what `make demo` runs): the whole appliance on the simulated rig, one part measured with push-button releases.

The real daemon (``service.daemon.Appliance``) runs with a temporary result
store: the sequencer, the gpiozero mock pins (the button is pressed on its
pin), the simulated pendulum read over a loopback Modbus RTU encoder link,
the identification, the SQLite store, the Modbus server on a free loopback
port (read back here with a real pymodbus client) and, when a broker is
given, MQTT (the result is received back from the broker). Without a broker
MQTT is skipped with a note. The part is judged with a demo recipe (nominal =
the simulated J, ±1 %, ``--releases`` releases, the guard-band rule): each
release and the part's verdict are printed, with the verdict registers.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import logging
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Iterator

from service.core import vocabulary as V
from service.errors import AddressInUse, InputFileError
from service.parts.outcome import PartOutcome
from service.settings.defaults import DEMO_EFFECTS, DEMO_INERTIA, SIM_ENCODER_NOISE, SIM_ENCODER_TIME_SCALE, sim_sample_timeout

EXIT_FAULT = 3


def add_arguments(p: argparse.ArgumentParser) -> None:
    from service.publish.web.settings import WebSettings
    from service.settings.schema import default_of

    p.add_argument("--mqtt", metavar="HOST[:PORT]", help="also publish to this MQTT broker and show the result it delivers "
                                                       "(default: MQTT skipped)")
    p.add_argument("--time-scale", type=float, default=SIM_ENCODER_TIME_SCALE, metavar="X",
                   help=f"simulated seconds per wall-clock second (default {SIM_ENCODER_TIME_SCALE:g}, at most 20; "
                        "faster, the simulated encoder's timestamps jitter enough to raise quality flags)")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="capture after the release, simulated s (default 20; 10 with --tensor)")
    p.add_argument("--inertia", "-J", type=float, default=DEMO_INERTIA, metavar="KG_M2",
                   help=f"true J of the simulated part (default {DEMO_INERTIA:g})")
    p.add_argument("--seed", type=int, default=1, help="noise seed (default 1)")
    p.add_argument("--releases", type=int, default=None, metavar="N",
                   help="releases of the demo part (its recipe asks for N; default 3; with --tensor, per orientation, "
                        "default 1)")
    p.add_argument("--nominal", type=float, metavar="KG_M2",
                   help="nominal J of the demo recipe (default: the simulated part's J; ±1 %% tolerance)")
    p.add_argument("--state-dir", metavar="DIR", help="keep the result store here (default: a temporary directory)")
    p.add_argument("--json", action="store_true", help="print the published result payload as JSON at the end")
    p.add_argument("--web-port", type=int, default=default_of(WebSettings, "port"), metavar="PORT",
                   help="serve the web page on 127.0.0.1:PORT (default %(default)s; a free port if it is taken; 0: any)")
    p.add_argument("--tensor", action="store_true",
                   help="run a guided six-orientation tensor set of a simulated bracket instead, and print the tensor's "
                        "error against the truth (--releases per orientation, default 1; --duration default 10)")
    p.add_argument("--serve", action="store_true",
                   help="keep the appliance and its web page running after the measurement, until Ctrl-C")


def _doc(args: argparse.Namespace, state_dir: str) -> dict:
    doc = {
        "device": {"id": "demo", "state_dir": state_dir, "log_level": "warning"},
        "sequencer": {"pre_trigger": 0.5, "capture_duration": args.duration,
                      "sample_timeout": sim_sample_timeout(args.time_scale)},
        "simulation": {"inertia": args.inertia, "time_scale": args.time_scale, "seed": args.seed, "sensor": "encoder",
                       "noise": SIM_ENCODER_NOISE, "effects": DEMO_EFFECTS},
        "modbus": {"host": "127.0.0.1", "port": 0},
        "web": {"host": "127.0.0.1", "port": args.web_port},
        "recipes": {"directory": str(Path(state_dir) / "recipes"), "active": DEMO_RECIPE},
    }
    if args.mqtt:
        host, _, port = args.mqtt.rpartition(":") if ":" in args.mqtt else (args.mqtt, "", "1883")
        try:
            doc["mqtt"] = {"host": host or "localhost", "port": int(port), "reconnect_min": 0.2, "reconnect_max": 2.0}
        except ValueError:
            raise InputFileError(f"--mqtt {args.mqtt!r}: expected HOST or HOST:PORT") from None
    return doc


DEMO_RECIPE = "demo-part"
DEMO_PART_ID = "DEMO-0001"


def _write_recipe(args: argparse.Namespace, state_dir: str) -> None:
    d = Path(state_dir) / "recipes"
    d.mkdir(parents=True, exist_ok=True)
    nominal = args.nominal if args.nominal is not None else args.inertia
    (d / f"{DEMO_RECIPE}.toml").write_text(
        "# the part type of `moi demo`: nominal ± 1 %, judged with the guard band of ISO 14253-1\n"
        f'[recipe]\nname = "{DEMO_RECIPE}"\nnumber = 1\nquantity = "J"\nnominal = {nominal!r}\n'
        f"tolerance_percent = 1.0\nreleases = {args.releases}\n", encoding="utf-8")


@contextlib.contextmanager
def state_directory(args: argparse.Namespace, prefix: str) -> Iterator[str]:
    """--state-dir, or a temporary directory removed at the end."""
    if args.state_dir:
        yield args.state_dir
        return
    with tempfile.TemporaryDirectory(prefix=prefix) as d:
        yield d


def run(args: argparse.Namespace) -> int:
    args.releases = (1 if args.tensor else 3) if args.releases is None else args.releases
    args.duration = (10.0 if args.tensor else 20.0) if args.duration is None else args.duration
    if not 1 <= args.releases <= 10:
        raise InputFileError(f"--releases must be in [1, 10], got {args.releases}")
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    if args.tensor:
        from .demo_tensor import run_in

        with state_directory(args, "moi-demo-tensor-") as state_dir:
            return run_in(args, state_dir)
    from service.config.appliance import parse_config
    from service.daemon import Appliance

    with state_directory(args, "moi-demo-") as state_dir:
        _write_recipe(args, state_dir)
        config = parse_config(_doc(args, state_dir), source="moi demo")
        app = Appliance(config, stop_grace=5.0)
        try:
            app.start()  # binding the port is the check: another program may take it at any moment before
        except AddressInUse as exc:
            if not args.web_port or exc.port != args.web_port:
                raise
            print(f"port {args.web_port} is taken: the web page goes on a free port")
            app = Appliance(config.with_publisher("web", dataclasses.replace(config.web, port=0)), stop_grace=5.0)
            app.start()
        return _run(app, args)


class _Watch:
    """Prints the sequencer's transitions as they come and collects the measurements it publishes."""

    def __init__(self, app) -> None:
        self.done = threading.Event()
        self.published: list = []
        self.t0 = app.devices.clock.now()
        self.wall0 = time.monotonic()
        self.scale = app.config.simulation.time_scale
        app.sequencer.subscribe(self.on_event)

    def on_event(self, e) -> None:
        # wall-clock seconds first: a simulated clock running faster would make identifying look slow
        sim = f"  (simulated clock {e.time - self.t0:.2f} s)" if self.scale != 1.0 else ""
        sys.stdout.write(f"[{time.monotonic() - self.wall0:7.2f} s] {e.state.value:<12} {e.reason}{sim}\n")
        sys.stdout.flush()
        if e.publishes:
            self.published.append(e.measurement)
        if e.ends_measurement:
            self.done.set()


def _run(app, args: argparse.Namespace) -> int:
    cfg = app.config
    watch = _Watch(app)
    consumer = _consumer(cfg, app) if cfg.mqtt is not None else None
    main = threading.Thread(target=app.run, name="moi-demo-main", daemon=True)
    main.start()
    status = 0
    try:
        _print_setup(app)
        app.command(V.PART_ID, "cli", {"part_id": DEMO_PART_ID})  # as the PLC writes it before the trigger
        if not _measure_part(app, watch):
            return EXIT_FAULT
        m = watch.published[-1]
        stored = app.store.get(m.id)
        assert stored is not None and stored.payload is not None  # an ok result, stored with its payload
        payload = stored.payload
        _print_result(app, m)
        _print_registers(app, payload)
        _print_part(payload)
        if consumer is not None:
            got = consumer.wait(payload["uuid"], 15)
            print(f"MQTT: result {payload['uuid']} " + ("received back from the broker" if got else
                                                         "not received within 15 s (is the broker reachable?)"))
        if args.json:
            print(json.dumps(payload, ensure_ascii=False))
        print(f"the result page: {app.web.url}results/{payload['uuid']}")
        _print_budget(app, m)
        if args.serve:
            _serve(main)
        status = 0
    finally:
        app.request_stop()
        main.join(30)
        if consumer is not None:
            consumer.close()
    return status if app.exit_status == 0 else app.exit_status


def _print_setup(app) -> None:
    """The simulated rig, where each door of the appliance is, and the demo recipe."""
    cfg = app.config
    sim = app.devices.sim
    print(f"simulated {cfg.rig.kind} rig: true J = {sim.inertia:g} kg·m², ω_n = {sim.pendulum.omega_n:.6g} rad/s, "
          f"effects {dict(sim.pendulum.effects)} (declared: {', '.join(cfg.rig.declared)}); "
          f"time × {cfg.simulation.time_scale:g}")
    print(f"Modbus TCP server on 127.0.0.1:{app.modbus.bound_port} (unit id {cfg.modbus.unit_id})")
    if cfg.mqtt is None:
        print("MQTT: skipped, no broker configured (try `moi demo --mqtt localhost`, or [mqtt] in the config of `moi run`)")
    else:
        print(f"MQTT: broker {cfg.mqtt.host}:{cfg.mqtt.port}, topics moi/{cfg.device_id}/...")
    print(f"result store: {app.config.state_dir}/results.db")
    token = Path(app.web.token_file).read_text(encoding="utf-8").strip()
    print(f"web page: {app.web.url}  (open it now; actions need the token {token}, kept in {app.web.token_file})")
    recipe = app.parts.recipe
    print(f"recipe {recipe.name} (version {recipe.version}): {recipe.spec.quantity} = {recipe.spec.nominal:g} "
          f"± {recipe.spec.upper - recipe.spec.nominal:.3g} kg·m², {recipe.releases} release(s) per part, "
          f"decision rule {recipe.spec.rule} (U = {recipe.spec.coverage_factor:g}·u_c)")


def _measure_part(app, watch: _Watch) -> bool:
    """Release the demo part as often as its recipe asks, pressing the push button's mock pin; each release's
    verdict printed. False (said on stderr) when a release brings no result."""
    cfg, recipe = app.config, app.parts.recipe
    pin = app.devices.button.pin
    limit = 60.0 + (cfg.sequencer.pre_trigger + cfg.sequencer.capture_duration) / cfg.simulation.time_scale
    for i in range(1, recipe.releases + 1):
        watch.done.clear()
        print(f"part {DEMO_PART_ID}, release {i} of {recipe.releases}: pressing the push button (gpiozero mock pin)")
        pin.drive_low()
        pin.drive_high()
        if not watch.done.wait(limit):
            print(f"moi demo: no result within {limit:.0f} s", file=sys.stderr)
            return False
        if len(watch.published) < i:
            print(f"moi demo: the measurement failed: {app.sequencer.last_fault}", file=sys.stderr)
            return False
        rel = PartOutcome.from_dict(app.store.get(watch.published[-1].id).payload).release
        assert rel is not None  # a recipe is active: every release is judged
        d = rel.decision
        print(f"  release {i}: {rel.quantity} = {_g(d.value, '.7g')} kg·m², u_c {_g(d.u_c)}, "
              f"U {_g(d.U)} → {d.verdict}" + (f" ({'; '.join(d.reasons)})" if d.reasons else ""))
    return True


def _print_result(app, m) -> None:
    """The last release's report and its error against the simulated truth."""
    from measurement.reports import result_report

    sim = app.devices.sim
    print()
    print(result_report(m.result))
    if m.result.J is not None:
        print(f"true J {sim.inertia:g} kg·m² → error {100 * (m.result.J / sim.inertia - 1):+.4f} %")
    print()


def _print_registers(app, payload: dict) -> None:
    """The result read back over Modbus TCP with a real client, beside its JSON values."""
    from pymodbus.client import ModbusTcpClient

    from measurement import flags as F
    from service.publish.modbus import registers as R

    unit = app.config.modbus.unit_id
    client = ModbusTcpClient("127.0.0.1", port=app.modbus.bound_port, timeout=3)
    client.connect()
    try:
        snap = R.read_snapshot(lambda a, n: client.read_input_registers(a, count=n, device_id=unit).registers)
    finally:
        client.close()
    assert snap is not None, "no consistent Modbus snapshot"  # nothing changes it while the demo reads
    print(f"Modbus registers read back over TCP (seq {snap['seq']}, uuid {snap['uuid']}):")
    for reg, key in (("J", "J"), ("J_std", "J_std"), ("omega_n", "omega_n"), ("damping_ratio", "damping_ratio"),
                     ("residual_rms", "residual_rms_after")):
        a = R.BY_NAME[reg].address
        print(f"  {a:>3}–{a + 1:<3} {reg:<14} {snap[reg]:.8g}   (JSON {payload[key]!r})")
    print(f"  {R.BY_NAME['flags'].address:>3}     flags          0x{snap['flags']:04x} "
          f"{F.flags_from_bits(snap['flags'] | snap['flags_high'] << 16) or '(none)'}")
    codes = {v: k for k, v in R.VERDICT_CODES.items()}
    for reg in ("verdict", "release_index", "releases", "part_id", "part_value", "part_U"):
        a = R.BY_NAME[reg].address
        value = codes.get(snap[reg], snap[reg]) if reg == "verdict" else snap[reg]
        print(f"  {a:>3}     {reg:<14} {value}")


def _print_part(payload: dict) -> None:
    """The part's value, its uncertainty and its verdict (once a release completed it)."""
    outcome = PartOutcome.from_dict(payload)
    part = outcome.part
    if part is None:
        return
    print()
    joint = part.joint
    how = "identified jointly" if joint else "weighted mean"
    fit_u = "joint u" if joint else "fit u"
    print(f"part {outcome.part_id}: {part.quantity} = {_g(part.value, '.7g')} kg·m² (releases "
          f"{[i + 1 for i in part.used]} {how}), s = {_g(part.std)}, Type A u = {_g(part.u_typeA)}, "
          f"{fit_u} = {_g(part.u_fit)}, systematic u = {_g(part.u_systematic)}, U = {_g(part.U)} kg·m²")
    if joint:
        c = joint["consistency"]
        print(f"  the releases against the joint ω_n {joint['omega_n']:.7g} rad/s: χ² {c['chi2']:.2f} on "
              f"{c['dof']} (p = {c['p']:.2g}), largest deviation {c['largest_z']:+.1f} σ")
    for e in part.excluded:
        print(f"  excluded release {e['index'] + 1}: {e['reason']}")
    spec = outcome.recipe or {}
    d = part.decision
    print(f"  tolerance [{spec['lower']:.7g}, {spec['upper']:.7g}], deviation {_g(d.deviation, '+.3g')}, "
          f"zone {d.zone} → VERDICT {d.verdict}" + (f" ({'; '.join(d.reasons)})" if d.reasons else ""))


def _print_budget(app, m) -> None:
    """The largest terms of the recipe quantity's uncertainty budget (one release)."""
    recipe = app.parts.recipe
    quantity = recipe.spec.quantity if recipe.spec is not None else "J"
    budget = m.result.uncertainty_budget.get(quantity)
    if budget is not None:
        top = sorted(budget.lines, key=lambda ln: -ln.share)[:3]
        print(f"uncertainty budget of {quantity} (one release): U = {_g(budget.U)} kg·m² "
              f"(k = {budget.coverage_factor:.3g}); largest terms: "
              + ", ".join(f"{ln.source} {100 * ln.share:.3g} %" for ln in top))


def _serve(main: threading.Thread) -> None:
    print("serving until Ctrl-C")
    try:
        while main.is_alive():
            main.join(0.5)
    except KeyboardInterrupt:
        pass


def _g(v, fmt: str = ".2g") -> str:
    return "-" if v is None else format(v, fmt)


class _consumer:
    """Subscribes to the demo's result topic (to show the broker delivered it)."""

    def __init__(self, cfg, app) -> None:
        import paho.mqtt.client as mqtt
        from paho.mqtt.enums import CallbackAPIVersion

        self.seen: set[str] = set()
        self.cond = threading.Condition()
        self.client = mqtt.Client(CallbackAPIVersion.VERSION2, client_id=f"moi-demo-consumer-{time.time_ns()}")
        topic = app.mqtt.topics.result
        self.client.on_connect = lambda c, u, f, rc, p: c.subscribe(topic, 1)
        self.client.on_message = self._on_message
        self.client.connect_async(cfg.mqtt.host, cfg.mqtt.port)
        self.client.loop_start()

    def _on_message(self, client, userdata, msg) -> None:
        try:
            uid = json.loads(msg.payload)["uuid"]
        except (ValueError, KeyError, TypeError):
            return
        with self.cond:
            self.seen.add(uid)
            self.cond.notify_all()

    def wait(self, uuid: str, timeout: float) -> bool:
        with self.cond:
            return self.cond.wait_for(lambda: uuid in self.seen, timeout)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()
