"""`moi measure --sim [--sensor encoder|camera] [--rig RIG.toml] [--effects ...]`: one push-button measurement on the simulated rig.

Everything below the sequencer is simulated but real in kind: the GPIO pins
are gpiozero mock pins (the button is pressed on its pin, the solenoid's
on/off is recorded on its pin), the pendulum swings according to the physics
with the chosen effects, and the swing is recorded by

* ``--sensor encoder`` (default): a pymodbus RTU server on a loopback socket
  read by the same Modbus client the device uses;
* ``--sensor camera``: a mock camera rendering the marker (the renderer of
  the vision tests, optionally yawed by ``--camera-yaw``) read by the same
  ``CameraAngleSensor`` the device uses, which fits and corrects the yaw.

Time runs ``--time-scale`` times faster than real time (default 1: the
simulated encoder's timestamps jitter by tens of µs of wall time, which a
faster clock stretches into a coloured residual, and the camera's frames are
rendered in real time).

While capturing, the elapsed and remaining time go to stderr about once a
second (when stderr is a terminal, or with ``--progress``); state lines show
the wall-clock time since the button press (and the simulated clock, labelled,
when it runs faster). ``--json`` keeps stdout to the one JSON object.
"""

from __future__ import annotations

import argparse
import logging
import sys
from typing import TYPE_CHECKING

from measurement.errors import InvalidInput
from service.settings import sensor_registry as sensors
from service.settings.defaults import DEMO_EFFECTS, DEMO_RIG, SIM_ENCODER_NOISE, sim_sample_timeout
from service.sources.files import read_rig

from .simulate import EFFECT_SYNTAX, parse_effects

if TYPE_CHECKING:  # pragma: no cover
    from firmware_host import Measurement


#: the demo rig, part and damping when no --rig is given
DEFAULT_RIG = DEMO_RIG
DEFAULT_EFFECTS = [f"{name}:{p}={v:g}" for name, params in DEMO_EFFECTS.items() for p, v in params.items()]

#: exit status when the measurement ended in FAULT (not a bug: exit 1; not bad input: exit 2)
EXIT_FAULT = 3

#: wall-clock seconds between two progress lines of the capture
PROGRESS_EVERY = 1.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    # the defaults are the settings classes' own (imported here, when this command is chosen: `moi --help`
    # loads no command)
    from firmware_host import SequencerConfig
    from service.settings.config import SimulationSettings
    from service.settings.schema import default_of

    def seq(name: str) -> object:
        return default_of(SequencerConfig, name)

    def sim(name: str) -> object:
        return default_of(SimulationSettings, name)

    p.add_argument("--sim", action="store_true",
                   help="use the simulated rig (or give --config for the configured hardware)")
    p.add_argument("--config", "-c", metavar="appliance.toml",
                   help="one measurement on the hardware of this configuration (commissioning: no daemon, no "
                        "store, no MQTT or Modbus); stop the daemon first")
    p.add_argument("--rig", metavar="RIG.toml",
                   help="rig file (default: the torsion demo rig, k = 0.3651 N·m/rad, declared viscous)")
    p.add_argument("--inertia", "-J", type=float, default=sim("inertia"), metavar="KG_M2",
                   help="true J of the simulated pendulum, kg·m² (default %(default)g)")
    p.add_argument("--effects", nargs="*", default=None, metavar="EFFECT",
                   help=f"{EFFECT_SYNTAX} (default without --rig: {' '.join(DEFAULT_EFFECTS)}; with --rig: none)")
    p.add_argument("--theta0", type=float, default=sim("theta0"), metavar="RAD",
                   help="release angle, rad (default %(default)g)")
    p.add_argument("--duration", type=float, default=seq("capture_duration"), metavar="S",
                   help="capture after the release, s of simulated time (default %(default)g)")
    p.add_argument("--pre-trigger", type=float, default=seq("pre_trigger"), metavar="S",
                   help="capture before the release, s (default %(default)g)")
    p.add_argument("--decay-threshold", type=float, default=seq("decay_threshold"), metavar="RAD",
                   help="end the capture early once the swing amplitude is below this, rad (default %(default)g: off)")
    p.add_argument("--sensor", choices=sensors.names(hardware=True), default=sim("sensor"),
                   help="what records the swing: the Modbus encoder (default) or the camera")
    p.add_argument("--time-scale", type=float, default=None, metavar="X",
                   help="simulated seconds per wall-clock second (default 1; at most 20 with the encoder, whose "
                        "timestamps jitter more in simulated time the faster it runs)")
    p.add_argument("--camera", metavar="CAM.toml",
                   help="camera file of the simulated camera (--sensor camera; default 640×480 px at 100 frames/s, "
                        "fx = 600 px, marker radius 0.10 m at 0.25 m)")
    p.add_argument("--camera-yaw", type=float, default=sim("camera_yaw_deg"), metavar="DEG",
                   help="yaw of the simulated camera, degrees (--sensor camera; estimated and corrected; "
                        "default %(default)g)")
    p.add_argument("--bits", type=int, default=sim("bits"), help="encoder resolution, bits per turn (default %(default)s)")
    p.add_argument("--noise", type=float, default=SIM_ENCODER_NOISE, metavar="RAD",
                   help=f"encoder angle noise σ, rad (default {SIM_ENCODER_NOISE:g}, about one count at 17 bits)")
    p.add_argument("--latency", type=float, default=sim("latency"), metavar="S",
                   help="encoder reply latency, s of real time (default %(default)g)")
    p.add_argument("--drop-rate", type=float, default=sim("drop_rate"), metavar="P",
                   help="fraction of encoder replies (or camera frames) lost (default %(default)g)")
    p.add_argument("--crc-rate", type=float, default=sim("crc_rate"), metavar="P",
                   help="fraction of encoder replies with a corrupted CRC (default %(default)g)")
    p.add_argument("--glitch-rate", type=float, default=sim("glitch_rate"), metavar="P",
                   help="fraction of encoder readings 1/128 turn off behind a correct CRC (default %(default)g)")
    p.add_argument("--seed", type=int, default=None, help="random seed of the encoder or camera noise and faults")
    p.add_argument("--no-discover", action="store_true", help="fit the declared model only (no discovery loop)")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object instead of the report")
    p.add_argument("--progress", action="store_true",
                   help="show the capture's progress on stderr even when it is not a terminal (it is shown on one)")


def run(args: argparse.Namespace) -> int:
    if args.config:
        return _measure_configured(args)
    if not args.sim:
        raise InvalidInput("moi measure: give --sim (the simulated rig) or --config FILE (the configured hardware)")
    if args.time_scale is None:
        args.time_scale = sensors.sensor(args.sensor).DEFAULT_TIME_SCALE
    if not (args.duration > 0 and args.pre_trigger >= 0):
        raise InvalidInput("--duration must be > 0 s and --pre-trigger >= 0 s")

    # imported here: `moi --help` must not pay for gpiozero/pymodbus
    from firmware_host import Sequencer, SequencerConfig
    from measurement import Options, Pendulum
    from service.devices.hardware import build_simulated
    from service.settings.config import SimulationSettings

    rig = read_rig(args.rig) if args.rig else DEFAULT_RIG
    tokens = args.effects if args.effects is not None else ([] if args.rig else DEFAULT_EFFECTS)
    effects = parse_effects(tokens, rig.kind)
    truth = Pendulum(rig, args.inertia, effects)
    sensor_values = _sensor_values(args)
    # each lost encoder reply already costs a time-out; pymodbus would log every one as an error
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)

    config = SequencerConfig(pre_trigger=args.pre_trigger, capture_duration=args.duration,
                             decay_threshold=args.decay_threshold, sample_timeout=sim_sample_timeout(args.time_scale))
    simulation = SimulationSettings(
        inertia=args.inertia, effects=effects, theta0=args.theta0, noise=args.noise, bits=args.bits,
        time_scale=args.time_scale, seed=args.seed, sensor=args.sensor, latency=args.latency, camera=args.camera,
        camera_yaw_deg=args.camera_yaw, camera_config=sensor_values.get("camera_config"), drop_rate=args.drop_rate, crc_rate=args.crc_rate,
        glitch_rate=args.glitch_rate)  # checks the time scale (InvalidInput names the limit)
    desc = ", ".join(f"{k}({', '.join(f'{p}={v:g}' for p, v in ps.items())})" for k, ps in effects.items()) or "no damping"
    out = sys.stderr if args.json else sys.stdout
    print(f"simulated {rig.kind} rig: true J = {truth.inertia:g} kg·m², ω_n = {truth.omega_n:.6g} rad/s, {desc}; "
          f"θ0 = {args.theta0:g} rad, time × {args.time_scale:g}", file=out)

    results: list[Measurement] = []
    with build_simulated(rig, simulation, config) as devices:
        for line in devices.notes:
            print(line, file=out)
        clock, solenoid, button = devices.clock, devices.solenoid, devices.button
        assert button is not None  # the simulated rig has its push button
        with Sequencer(clock=clock, solenoid=solenoid, sensor=devices.sensor, rig=rig, sink=results.append,
                       config=config, options=Options(discover=not args.no_discover), button=button) as seq:
            printer = _StatePrinter(clock, args.time_scale, out, config.capture_duration, _show_progress(args))
            seq.subscribe(printer)
            print("pressing the button", file=out)
            # the mock factory is process-wide and a pin's history with it: this measurement's pulses only
            history_from = max(0, len(solenoid.pin.states) - 1)
            button.pin.drive_low()   # pull-up button: pressed pulls the line low
            button.pin.drive_high()
            try:
                last = seq.run_until_settled(timeout=args.pre_trigger + args.duration + 120.0 * args.time_scale)
            finally:
                printer.close()
        states = solenoid.pin.states[history_from:]
        on_times = [s.timestamp for prev, s in zip(states, states[1:]) if prev.state]
        print(f"solenoid: {len(on_times)} pulse(s), on for {', '.join(f'{x * 1e3:.1f}' for x in on_times)} ms "
              f"(real time), now {'ON' if solenoid.is_active else 'off'}", file=out)
    if results:
        _print_acquisition(results[0], out)

    status = _print_result(results, seq, last, args.json,
                           {"J": truth.inertia, "omega_n": truth.omega_n, "effects": effects})
    if status != 0 or args.json:
        return status
    m = results[0]
    if m.result.J is not None:
        print(f"true J {truth.inertia:g} kg·m² → error {100 * (m.result.J / truth.inertia - 1):+.4f} %")
    return 0


def _measure_configured(args: argparse.Namespace) -> int:
    """One measurement on the devices of the configuration, built by the daemon's own builder."""
    from firmware_host import Sequencer
    from service.config.appliance import load_config
    from service.config.check import pin_problems
    from service.devices.hardware import build_devices
    from service.errors import ConfigError, StartupError
    from service.persistence.state_dir import lock_state_dir

    config = load_config(args.config)
    if pin_problems(config):
        raise ConfigError("; ".join(pin_problems(config)))
    out = sys.stderr if args.json else sys.stdout
    try:
        lock = lock_state_dir(config.state_dir)  # not while the daemon drives the same solenoid
    except StartupError as exc:
        print(f"moi measure: error: {exc}", file=sys.stderr)
        return EXIT_FAULT
    results: list = []
    try:
        with build_devices(config) as devices:
            for line in devices.notes:
                print(line, file=out)
            with Sequencer(clock=devices.clock, solenoid=devices.solenoid, sensor=devices.sensor, rig=config.rig,
                           sink=results.append, config=config.sequencer, options=config.identification,
                           indicator=devices.indicator) as seq:
                c = config.sequencer
                printer = _StatePrinter(devices.clock, config.simulation.time_scale if config.simulated else 1.0, out,
                                        c.capture_duration, _show_progress(args))
                seq.subscribe(printer)
                print(f"{'simulated' if config.simulated else 'hardware'} rig of {args.config}: releasing", file=out)
                seq.request_measurement("cli")
                try:
                    last = seq.run_until_settled(timeout=c.pre_trigger + c.capture_duration + c.identify_timeout + 30.0)
                finally:
                    printer.close()
        if results:
            _print_acquisition(results[0], out)
    finally:
        import os
        os.close(lock)
    return _print_result(results, seq, last, args.json)


def _show_progress(args: argparse.Namespace) -> bool:
    """Progress lines on stderr: with --progress, or when stderr is a terminal."""
    return bool(getattr(args, "progress", False)) or sys.stderr.isatty()


class _StatePrinter:
    """Prints each state as a line, and the capture's progress on stderr while it runs.

    State lines start with the wall-clock seconds since the printer was made (the button press);
    when the sequencer's clock runs faster than real time its reading is added, labelled
    "simulated", so a 30 s simulated capture is not read as 30 s waited. While CAPTURING, a thread
    prints the capture's elapsed and remaining time to stderr every ``PROGRESS_EVERY`` s of wall
    time: rewritten in place on a terminal, one line each otherwise; never on stdout.
    """

    def __init__(self, clock, time_scale: float, out, capture_duration: float, progress: bool) -> None:
        import threading
        import time

        self._clock, self._scale, self._out = clock, time_scale, out
        self._duration = capture_duration
        self._progress = progress
        self._tty = sys.stderr.isatty()
        self._wall0 = time.monotonic()
        self._t0 = clock.now()
        self._lock = threading.Lock()
        self._pending = False          # a progress line without its newline is on the terminal
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def __call__(self, e) -> None:
        import time

        from firmware_host import State

        wall = time.monotonic() - self._wall0
        sim = f"  (simulated clock {e.time - self._t0:.2f} s)" if self._scale != 1.0 else ""
        hint = "; identifying…" if e.state is State.IDENTIFYING else ""
        with self._lock:
            self._end_line()
            print(f"[{wall:7.2f} s] {e.state.value:<12} {e.reason}{hint}{sim}", file=self._out, flush=True)
        if e.state is State.CAPTURING and self._progress and self._thread is None:
            import threading

            self._thread = threading.Thread(target=self._report, args=(e.time,), name="moi-measure-progress",
                                            daemon=True)
            self._thread.start()
        elif e.state is not State.CAPTURING:
            self._stop_thread()

    def close(self) -> None:
        self._stop_thread()

    def _stop_thread(self) -> None:
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(2.0)
        with self._lock:
            self._end_line()
        self._stop.clear()

    def _end_line(self) -> None:  # with the lock held
        if self._pending:
            sys.stderr.write("\n")
            sys.stderr.flush()
            self._pending = False

    def _report(self, start: float) -> None:
        # throttle: one line per PROGRESS_EVERY s of wall time, until the state changes
        while not self._stop.wait(PROGRESS_EVERY):
            elapsed = min(max(self._clock.now() - start, 0.0), self._duration)
            left = (self._duration - elapsed) / self._scale  # wall-clock s
            if self._scale == 1.0:
                line = f"capturing: {elapsed:4.0f} s of {self._duration:g} s, {left:.0f} s left"
            else:
                line = (f"capturing: {elapsed:5.1f} s of {self._duration:g} s simulated (time × {self._scale:g}), "
                        f"{left:.0f} s left in real time")
            with self._lock:
                if self._stop.is_set():
                    return
                if self._tty:
                    sys.stderr.write("\r\033[K" + line)
                    self._pending = True
                else:
                    sys.stderr.write(line + "\n")
                sys.stderr.flush()


def _print_acquisition(m, out) -> None:
    """What the encoder kept and dropped: late replies are left out of the trace, and said so here."""
    enc = m.result.acquisition.get("encoder")
    if not enc or "late_replies" not in enc:  # the in-process simulated sensor has no link
        return
    req = enc.get("requests") or 0
    late, errors = enc.get("late_replies", 0), enc.get("errors", 0)
    share = f" ({100 * late / req:.1f} % of {req} requests)" if req else ""
    print(f"encoder: {enc.get('samples', 0)} samples kept; dropped: {late} late replies{share} whose time stamp "
          f"would be uncertain, {errors} failed reads", file=out)


def _print_result(results: list, seq, last, as_json: bool, truth: dict | None = None) -> int:
    """The one measurement's result (report, or JSON with the truth of a simulation); EXIT_FAULT without one."""
    if not results:
        reason = seq.last_fault or (last.reason if last else "no result")
        print(f"moi measure: measurement failed: {reason}", file=sys.stderr)
        return EXIT_FAULT
    m = results[0]
    if as_json:
        import json
        d = m.to_dict() | ({"truth": truth} if truth is not None else {})
        sys.stdout.write(json.dumps(d, ensure_ascii=False, allow_nan=False) + "\n")
    else:
        from measurement.reports import result_report

        print(result_report(m.result))
    return 0


def _sensor_values(args: argparse.Namespace) -> dict:
    """The simulated sensor's settings, completed by its own module before anything is opened (the camera reads
    its camera file, --camera, else the demo camera's): a bad one is one line naming the option."""
    from service.errors import ConfigError
    if not (abs(args.camera_yaw) < 20 and args.camera_yaw == args.camera_yaw):
        raise InvalidInput(f"--camera-yaw must be within ±20°, got {args.camera_yaw:g}")
    values = {"camera": args.camera}

    def fail(key: str | None, message: str) -> ConfigError:
        return ConfigError(f"--{key or args.sensor}: {message}")

    sensors.sensor(args.sensor).simulation_values(values, fail)
    return values
