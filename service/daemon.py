"""The appliance daemon: sequencer, result store, the publishers and systemd, in one main loop.

Threads and who owns what:

* the main loop (``Appliance.run``, the caller's thread) polls the sequencer
  every ``poll_interval`` s, executes the commands queued by the button, the
  Modbus coils and MQTT, refreshes the live Modbus registers and pings the
  systemd watchdog, only after an iteration that completed (a hung loop
  therefore gets the daemon restarted by systemd);
* the sequencer calls back on the main loop's thread: state events (handed to
  every publisher) and the result sink, which stores the measurement and its
  outbox rows in one SQLite transaction, then hands the stored result to every
  publisher (the Modbus snapshot swaps, the outbox sender wakes, the web page
  draws its plot); nothing is published before the store has it;
* the publishers (``service.publish.port``: Modbus, MQTT, the web page) run in
  their own threads and only enqueue commands / acknowledgements; the daemon
  holds them in a list and never names one.

Only ``run``'s loop catches broadly: an unexpected error becomes a FAULT of
the sequencer (solenoid off), published like any state; a component thread
that died ends the daemon with status 3 so that systemd restarts it.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import datetime as _dt
import logging
import queue
import subprocess
import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any, Callable, Mapping

from firmware_host import Event, Measurement, Sequencer, State
from measurement import IdentificationResult, Rig, Trace, identify
from measurement import flags as F
from measurement.errors import InvalidInput
from measurement.integrator import is_compiled
from service.config.appliance import Config
from service.core import vocabulary as V
from service.core.live import LiveStatus
from service.devices.hardware import Devices, build_devices
from service.parts.recipes import PartTracker, Recipe, RecipeBook, RecipeError
from service.parts.tensor_set import COMPLETE, OpenSetFile, TensorSet, interrupted
from service.persistence.salvage import quarantine_store
from service.persistence.store import Store
from service.publish import registry
from service.publish.payload import iso_utc, result_payload
from service.publish.port import ApplianceView, Publisher
from service.publish.replies import CONTACT, CommandReply, ReplyTo, calibration_words

from . import __version__
from .contention import CaptureWatch
from .errors import ServiceError, StartupError, StoreDamaged, StoreError
from .notify import Notifier

log = logging.getLogger("moi.daemon")

#: exit statuses of ``run``
EXIT_OK = 0
EXIT_RUNTIME_FAILURE = 3

#: at most one "trigger ignored" line per this many seconds, s
IGNORED_LOG_INTERVAL = 10.0

#: the lock file in the state directory that makes a second daemon on it stop at start
LOCK_NAME = "moi.lock"

#: how often the live status looks again whether the rig's calibration is due, s
CALIBRATION_CHECK_INTERVAL = 60.0

#: consecutive failing loop iterations after which the daemon gives up (systemd restarts it)
MAX_LOOP_FAILURES = 20


class Appliance:
    """The whole appliance. ``start()``, then ``run()`` (blocks until ``request_stop()``).

    config: the validated configuration. notifier: systemd notification (default: from the
    environment). devices: injected devices (default: built from the config).
    wall_clock: Unix time, s (timestamps in the store and the payloads).
    """

    def __init__(self, config: Config, *, notifier: Notifier | None = None, devices: Devices | None = None,
                 wall_clock: Callable[[], float] = time.time, poll_interval: float = 0.02,
                 stop_grace: float = 10.0, identifier: Callable[[Trace, Rig], IdentificationResult] | None = None) -> None:
        self.config = config
        self.notifier = notifier or Notifier()
        self.wall_clock = wall_clock
        self.poll_interval = poll_interval
        self.stop_grace = stop_grace
        self._identifier = identifier or (lambda trace, rig: identify(trace, rig, self.config.identification))
        self._devices = devices
        self.devices: Devices | None = None
        self.store: Store | None = None
        self.publishers: list[Publisher] = []  # started, in start order
        self.sequencer: Sequencer | None = None
        self._commands: queue.SimpleQueue[tuple[str, str, Mapping[str, Any] | None, ReplyTo | None]] = queue.SimpleQueue()
        self._calls: queue.SimpleQueue[tuple[Callable[[], Any], concurrent.futures.Future]] = queue.SimpleQueue()
        self._wakeup = threading.Event()
        self._stop = threading.Event()
        self._compiling: subprocess.Popen | None = None  # the integrator compiled on a first run
        self._started_runs = 0
        self._capture_watch = CaptureWatch(lambda: sum(p.capture_requests() for p in self.publishers))
        # measurement id → (monotonic time of ARMED, trigger source): a run's start is the wall clock at its end
        # less the monotonic time it took, so a step of the wall clock never gives a negative duration
        self._run_started: dict[str, tuple[float, str]] = {}
        self._accepted_source = "unknown"  # source of the last accepted trigger (paired with the next ARMED)
        self._accepted_reply: ReplyTo | None = None  # who hears the outcome of the last accepted trigger
        self._run_reply: dict[str, ReplyTo] = {}  # measurement id → who hears its outcome
        # the part ID and recipe of the last accepted trigger, and of each run (measurement id → them)
        self.parts = PartTracker(config.recipes or RecipeBook(None), config.active_recipe)
        self._accepted_part: tuple[str | None, Recipe | None] = (None, None)
        self._run_part: dict[str, tuple[str | None, Recipe | None]] = {}
        self._current_recipe: Recipe | None = None
        self.tensor_set: TensorSet | None = None  # the guided set of a tensor recipe (open or just finished)
        self._last_status = ""
        self.loop_iterations = 0
        self.last_loop_error: str | None = None
        self.stored: list[str] = []  # UUIDs stored since start (ok, failed, aborted), in order
        self._durable_results: deque[str] = deque(maxlen=16)  # UUIDs of the latest results the store holds
        self._stored_cond = threading.Condition()
        self.exit_status = EXIT_OK
        self._stopping = False
        self._lock_fd: int | None = None
        self._ignored_triggers = 0
        self._ignored_logged_at = -float("inf")
        self._refused_logged_at = -float("inf")
        self._armed_at: float | None = None  # sequencer clock time of the last ARMED, s (None: not armed)
        # (monotonic s, recipe, due, refused) of the last look at the rig's calibration (the live status'
        # calibration_due and measure_refused)
        self._calibration_checked: tuple[float, Recipe | None, bool, bool] = (-float("inf"), None, False, False)

    # --- commands (any thread; never blocks) ----------------------------------------------------
    def command(self, name: str, source: str, data: Mapping[str, Any] | None = None,
                reply: ReplyTo | None = None) -> None:
        """Queue a command from ``source`` ("button", "modbus", "mqtt", "cli", "web"): a name of
        ``service.core.vocabulary.COMMANDS`` with its data (a trigger's may carry ``part_id``, and ``recipe``
        as a name or number). ``reply`` hears the outcome (``service.publish.replies``) on the main loop
        thread."""
        self._commands.put((name, source, data, reply))
        self._wakeup.set()

    def call_soon(self, fn: Callable[[], Any]) -> concurrent.futures.Future:
        """Run ``fn()`` on the main loop between two iterations (any thread; never blocks): device access
        that must not overlap a measurement, e.g. the web page's camera snapshot. The future has its result."""
        fut: concurrent.futures.Future = concurrent.futures.Future()
        self._calls.put((fn, fut))
        self._wakeup.set()
        return fut

    def request_stop(self) -> None:
        self._stop.set()
        self._wakeup.set()

    # --- start ------------------------------------------------------------------------------------
    def start(self) -> None:
        """Open the store, start Modbus and MQTT, build the devices and the sequencer; then READY."""
        cfg = self.config
        try:
            self._lock_state_dir()
            self.store = self._open_store()
            view = ApplianceView(self)
            enabled = [(entry.load(), settings) for entry in registry.PUBLISHERS
                       if (settings := cfg.publishers.get(entry.name)) is not None]
            self._start_publishers([(kind, s) for kind, s in enabled if kind.EARLY], view)
            self.devices = self._devices or build_devices(cfg)
            d = self.devices
            # the button is wired through the command queue like the other sources, so every
            # trigger is logged and executed the same way on the main loop
            self.sequencer = Sequencer(clock=d.clock, solenoid=d.solenoid, sensor=d.sensor, rig=cfg.rig,
                                       sink=self._store_measurement, config=cfg.sequencer,
                                       options=cfg.identification, button=None, indicator=d.indicator,
                                       identifier=self._identify)
            if d.button is not None:
                d.button.when_pressed = lambda: self.command(V.TRIGGER, "button")
            self.sequencer.subscribe(self._on_event)
            if not is_compiled(cfg.rig.kind):
                # a device's first run: the integrator is compiled (some 10 s on a Pi) in a child
                # process now, not while the first swing waits for its result, and not on a thread
                # here, whose imports would hold the interpreter lock against a capture's reader
                self._compiling = subprocess.Popen([sys.executable, "-m", "measurement.integrator", cfg.rig.kind],
                                                   stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                                   stderr=subprocess.DEVNULL)
            # the others once the sequencer exists, in PUBLISHERS' order (an outbox sender delivers at
            # once; the live status follows its progress once the main loop runs, right after this)
            self._start_publishers([(kind, s) for kind, s in enabled if not kind.EARLY], view)
        except BaseException:
            self._shutdown_components()
            raise
        self._recover_set()
        self._open_set()  # a tensor recipe active from the configuration: its set waits for the first release
        self._refresh_live()
        self._to_publishers("on_state", self._state_message("IDLE", "IDLE", "daemon started", None), None)
        where = [w for p in self.publishers if (w := p.where())] or ["no publisher"]
        log.info("moi %s ready (%s rig; %s; store %s)", __version__, "simulated" if cfg.simulated else "hardware",
                 ", ".join(where), self.store.path)
        self.notifier.ready(f"idle; {', '.join(where)}")

    def _start_publishers(self, kinds: list[tuple[type[Publisher], Any]], view: ApplianceView) -> None:
        for kind, settings in kinds:
            publisher = kind.build(settings, view)
            publisher.start()
            self.publishers.append(publisher)

    def _stop_publishers(self, publishers: list[Publisher]) -> None:
        for p in reversed(publishers):
            try:
                p.stop()
            except Exception:
                log.exception("%s stop failed", p.NAME)
            self.publishers.remove(p)

    def _to_publishers(self, hook: str, *args: Any) -> None:
        """Call ``hook`` of every publisher (main loop thread; hooks never block)."""
        for p in self.publishers:
            getattr(p, hook)(*args)

    def publisher(self, name: str) -> Publisher | None:
        """The running publisher of configuration table ``name``, or None."""
        return next((p for p in self.publishers if name == p.NAME), None)

    def __getattr__(self, name: str) -> Any:
        # app.modbus, app.mqtt, app.web...: a publisher by its table's name (None when off), for tests and tools
        if any(entry.name == name for entry in registry.PUBLISHERS):
            return next((p for p in self.__dict__.get("publishers", ()) if name == p.NAME), None)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def publisher_health(self) -> dict[str, dict[str, Any] | None]:
        """Each publisher's health under its name (None when it is off), for the health page."""
        out: dict[str, dict[str, Any] | None] = {}
        for entry in registry.PUBLISHERS:
            if entry.in_health:
                p = self.publisher(entry.name)
                out[entry.name] = p.health() if p is not None else None
        return out

    def _lock_state_dir(self) -> None:
        self._lock_fd = lock_state_dir(self.config.state_dir)

    def _unlock_state_dir(self) -> None:
        if self._lock_fd is not None:
            import os
            os.close(self._lock_fd)  # closing the descriptor releases the lock
            self._lock_fd = None

    def _open_store(self) -> Store:
        """The store, after the reads a start does; a damaged one is moved aside and what can be
        read is salvaged into a new one (a restart loop on a damaged file would stop the appliance
        for good, and deleting it would lose results)."""
        state_dir = self.config.state_dir
        try:
            store = Store(state_dir)
            try:
                store.outbox_count()
                store.latest("ok")
                store.outbox_pending(limit=10)
            except BaseException:
                store.close()
                raise
            return store
        except StoreDamaged as exc:
            log.error("%s", exc)
        aside, health = quarantine_store(state_dir, self.wall_clock)
        log.error("the damaged result store was moved to %s; a new store holds what could be read (%s)", aside,
                  health.summary())
        return Store(state_dir)

    # --- the main loop ---------------------------------------------------------------------------------
    def run(self, until: Callable[[], bool] | None = None) -> int:
        """Run until ``request_stop()`` (or ``until()`` is true), then stop gracefully. Returns the exit status."""
        failures = 0
        try:
            while not self._stop.is_set() and not (until is not None and until()):
                try:
                    self._iteration()
                    failures = 0
                    self.last_loop_error = None
                except _Fatal as exc:
                    log.error("%s; stopping", exc)
                    self.exit_status = EXIT_RUNTIME_FAILURE
                    break
                except Exception as exc:  # the outermost loop: an error becomes a FAULT, the loop goes on
                    failures += 1
                    self.last_loop_error = f"{type(exc).__name__}: {exc}"
                    log.exception("main loop iteration failed (%d in a row)", failures)
                    self._fault(f"internal error: {self.last_loop_error}")
                    if failures >= MAX_LOOP_FAILURES:
                        log.error("main loop failed %d times in a row; stopping", failures)
                        self.exit_status = EXIT_RUNTIME_FAILURE
                        break
                self._wakeup.wait(self._next_wait())
                self._wakeup.clear()
        finally:
            self.stop()
        return self.exit_status

    def _next_wait(self) -> float:
        """Real seconds until the next poll: ``poll_interval``, or less when the release is due sooner. On
        the simulated rig at a large time scale a whole poll interval is many simulated seconds, which the
        pre-trigger would otherwise grow by (20 s at ×1000)."""
        seq, armed = self.sequencer, self._armed_at
        if seq is None or armed is None or seq.state is not State.ARMED or self.devices is None:
            return self.poll_interval
        due = armed + self.config.sequencer.pre_trigger - self.devices.clock.now()
        return min(self.poll_interval, max(0.0, due / self._clock_scale()))

    def _iteration(self) -> None:
        assert self.sequencer is not None
        # poll first: a trigger that arrived during PUBLISHING finds the IDLE that follows it
        self.sequencer.poll()
        self._drain_commands()
        self._run_calls()
        self._check_components()
        self._refresh_live()
        self.loop_iterations += 1
        # the watchdog is fed only here, after a complete healthy iteration
        if self.notifier.watchdog_due():
            self.notifier.watchdog()
        status = self._status_text()
        if status != self._last_status:
            self._last_status = status
            self.notifier.status(status)

    def _drain_commands(self) -> None:
        while True:
            try:
                name, source, data, reply = self._commands.get_nowait()
            except queue.Empty:
                return
            outcome = self._execute(name, source, data, reply)
            if reply is not None:
                reply(outcome)

    def _execute(self, name: str, source: str, data: Mapping[str, Any] | None,
                 reply: ReplyTo | None) -> CommandReply:
        """Act on one command; the outcome its source hears."""
        seq = self.sequencer
        assert seq is not None

        def refused(reason: str, detail: str = "") -> CommandReply:
            return CommandReply(name, "refused", reason, detail)

        command = V.COMMANDS.get(name)
        if command is None:
            log.warning("unknown command %r from %s", name, source)
            return refused("unknown_command", f"{name!r}")
        if command.sets_part and (data or command.act == "part"):
            if seq.busy:
                self._log_ignored(f"{name} from {source} refused: a measurement runs (the part cannot change "
                                  "during it)")
                return refused("busy")
            try:
                self._apply_part_data(data or {})
            except InvalidInput as exc:
                log.warning("%s from %s refused: %s", name, source, exc)
                return refused("unknown_recipe" if isinstance(exc, RecipeError) else "malformed", str(exc))
            if command.act == "part":
                return CommandReply(name, "done")
        return self._ACTS[command.act](self, name, command, source, data, reply)

    def _act_measure(self, name: str, command: V.Command, source: str, data: Mapping[str, Any] | None,
                     reply: ReplyTo | None) -> CommandReply:
        """A trigger (its part data applied already): a measurement starts, or the reason it cannot."""
        seq = self.sequencer
        assert seq is not None
        unwritable = self._store_unwritable()
        if unwritable is not None:
            self._log_refused(logging.ERROR, source, unwritable)
            return CommandReply(name, "refused", "store_unwritable", unwritable)
        block = self.measure_block() if seq.state is State.IDLE else None
        if block is not None:
            self._log_refused(logging.WARNING, source, block["detail"])
            self._show_block(True, again=True)
            return CommandReply(name, "refused", "calibration_due", block["detail"])
        if seq.request_measurement(source):
            self._accepted_source = source
            self._accepted_reply = reply
            self._accepted_part = (self.parts.part_id, self.parts.recipe)
            self._open_set()
            return CommandReply(name, "accepted")
        self._log_ignored(f"trigger from {source} ignored (state {seq.state.value})")
        state = seq.state
        return CommandReply(name, "refused", "fault" if state is State.FAULT else "busy" if seq.busy else "not_ready",
                            f"state {state.value}")

    def _act_stop(self, name: str, command: V.Command, source: str, data: Mapping[str, Any] | None,
                  reply: ReplyTo | None) -> CommandReply:
        """Abort the running measurement, or acknowledge a FAULT (an abort does both)."""
        seq = self.sequencer
        assert seq is not None
        if seq.state is State.FAULT:
            seq.abort(f"fault acknowledged by {source}")
            return CommandReply(name, "done")
        if name == V.ABORT and seq.abort(f"aborted by {source}"):
            return CommandReply(name, "done")
        log.info("%s from %s: nothing to %s", name, source, "abort" if name == V.ABORT else "acknowledge")
        return CommandReply(name, "refused", "nothing_to_abort")

    def _act_set(self, name: str, command: V.Command, source: str, data: Mapping[str, Any] | None,
                 reply: ReplyTo | None) -> CommandReply:
        """An operator action of the tensor set: the coil's own (``set_action``) or the data's ``action``."""
        action = command.set_action or str((data or {}).get("action"))
        return self._set_action(action, (data or {}).get("orientation"), source, name)

    #: how the daemon acts on each ``Command.act`` but "part" (whose data is applied in ``_execute``)
    _ACTS: dict[str, Callable[..., CommandReply]] = {"measure": _act_measure, "stop": _act_stop, "set": _act_set}

    def _log_ignored(self, what: str) -> None:
        """One line per IGNORED_LOG_INTERVAL for the commands a stuck button or a looping client repeats."""
        self._ignored_triggers += 1
        now = time.monotonic()
        if now - self._ignored_logged_at >= IGNORED_LOG_INTERVAL:
            log.info("%s; %d command(s) ignored or refused since the last such line", what, self._ignored_triggers)
            self._ignored_logged_at, self._ignored_triggers = now, 0

    def _log_refused(self, level: int, source: str, why: str) -> None:
        """A refused trigger in the log, at most one line per IGNORED_LOG_INTERVAL (a stuck button repeats it)."""
        now = time.monotonic()
        if now - self._refused_logged_at >= IGNORED_LOG_INTERVAL:
            log.log(level, "trigger from %s refused: %s", source, why)
            self._refused_logged_at = now

    def _store_unwritable(self) -> str | None:
        """Why no measurement may start (its result could not be kept), or None. After a failed write
        a write is tried again here, so measuring resumes as soon as space is freed."""
        store = self.store
        if store is None or store.write_failure is None or store.writable():
            return None
        return (f"the result store cannot be written ({store.write_failure}); free space in "
                f"{str(self.config.state_dir)!r}: the results kept so far are safe and still delivered")

    def _apply_part_data(self, data: Mapping[str, Any]) -> None:
        """Select a recipe and/or set the part ID (InvalidInput when unknown or malformed)."""
        if data.get("recipe") is not None:
            r = self.parts.select(data["recipe"])
            log.info("recipe %s", f"{r.number} {r.name!r} (version {r.version}) active" if r else "deselected")
            self._to_publishers("on_recipe", r)
        if "part_id" in data:
            self.parts.set_part_id(data["part_id"])
            self._to_publishers("on_part_id", self.parts.part_id)
        self._open_set()

    # --- the guided tensor set (main loop thread) ------------------------------------------------------
    def _open_set(self) -> None:
        """Open a tensor set when the active recipe declares a tensor plan and none runs for it and this part
        (a finished set is shown until the next trigger or selection, which starts the next one); a running
        set of another recipe or part is aborted (its releases stay stored)."""
        recipe, part_id = self.parts.recipe, self.parts.part_id
        current = self.tensor_set
        if current is not None and not current.done:
            if recipe is current.recipe and part_id == current.part_id:
                return
            current.act("abort")
            current.error = "a different recipe or part ID was selected"
            self._finish_set(current)
        if recipe is None or recipe.tensor is None:
            return
        self.tensor_set = TensorSet(recipe, recipe.rig_for(self.config.rig), part_id, self.wall_clock())
        log.info("tensor set %s started (%s, part %s): %s", self.tensor_set.uuid, recipe.name, part_id or "-",
                 self.tensor_set.instruction())
        self._publish_set()

    def _set_action(self, action: str, orientation: Any, source: str, name: str = "set") -> CommandReply:
        s = self.tensor_set
        if s is None or s.done:
            log.warning("set %s from %s: no tensor set is running", action, source)
            return CommandReply(name, "refused", "no_tensor_set")
        assert self.sequencer is not None
        if self.sequencer.busy and action != "abort":
            log.warning("set %s from %s refused: a measurement runs", action, source)
            return CommandReply(name, "refused", "busy")
        try:
            s.act(action, None if orientation is None else str(orientation))
        except InvalidInput as exc:
            log.warning("set %s from %s refused: %s", action, source, exc)
            return CommandReply(name, "refused", "malformed", str(exc))
        log.info("tensor set %s: %s by %s; %s", s.uuid, action, source, s.instruction())
        if s.done:  # act() may have ended the set (mypy keeps the narrowing of s.done above across the call)
            self._finish_set(s)  # type: ignore[unreachable]
        self._publish_set()
        return CommandReply(name, "done")

    def _finish_set(self, s: TensorSet, record: dict[str, Any] | None = None) -> None:
        """Store a finished set (complete, failed, aborted or interrupted) and hand it to the publishers."""
        assert self.store is not None
        record = record or s.to_dict()
        try:
            self.store.record_tensor_set(record, started_at=s.started_at, finished_at=self.wall_clock())
        except ServiceError:
            log.exception("could not store the tensor set %s", s.uuid)
            return
        OpenSetFile(self.config.state_dir).drop()
        if s.status == COMPLETE and s.result is not None:
            r = s.result
            log.info("tensor set %s complete: principal moments %s kg·m², flags %s", s.uuid,
                     ", ".join(f"{v:.6g}" for v in r.principal_moments), ", ".join(r.flags) or "none")
        self._to_publishers("on_tensor_set", record | {"device_id": self.config.device_id,
                                                      "timestamp": self.wall_clock()})

    def _interrupt_set(self, why: str) -> None:
        """A running set with releases, cut short: stored as interrupted (a new set begins at the next start)."""
        s = self.tensor_set
        if s is not None and not s.done and any(s.releases().values()) and self.store is not None:
            log.warning("tensor set %s interrupted at %s: %s", s.uuid, s.instruction(), why)
            self._finish_set(s, interrupted(s.to_dict(), why))

    def _recover_set(self) -> None:
        """The set a kill cut short (its file is left): stored as interrupted, and said; a new set starts."""
        left = OpenSetFile(self.config.state_dir).left()
        if left is None or self.store is None:
            return
        record = interrupted(left, "the daemon was stopped during the set without storing it")
        try:
            self.store.record_tensor_set(record, started_at=left.get("started_at"), finished_at=self.wall_clock())
        except ServiceError:
            log.exception("could not store the interrupted tensor set %s", left["uuid"])
            return
        OpenSetFile(self.config.state_dir).drop()
        log.warning("tensor set %s (%s, part %s) was interrupted: %s; a new set starts at the first orientation",
                    left["uuid"], left.get("recipe"), left.get("part_id") or "-", record["error"])

    def _publish_set(self) -> None:
        if self.tensor_set is not None and not self.tensor_set.done:
            OpenSetFile(self.config.state_dir).keep(self.tensor_set)
        progress = self.set_progress()
        if progress is not None:
            self._to_publishers("on_set", progress)
        self._refresh_live()

    def set_progress(self) -> dict[str, Any] | None:
        """The tensor set's progress with the operator's instruction (None: no set)."""
        s = self.tensor_set
        if s is None:
            return None
        return s.progress() | {"instruction": s.instruction(), "device_id": self.config.device_id}

    def _run_calls(self) -> None:
        while True:
            try:
                fn, fut = self._calls.get_nowait()
            except queue.Empty:
                return
            if fut.set_running_or_notify_cancel():
                try:
                    fut.set_result(fn())
                except Exception as exc:  # the caller gets it; the main loop goes on
                    fut.set_exception(exc)

    def _check_components(self) -> None:
        if self._compiling is not None and self._compiling.poll() is not None:
            self._compiling = None  # the kernel is compiled (poll reaped the child)
        for p in self.publishers:
            why = p.failure()
            if why is not None:
                raise _Fatal(why)

    def _fault(self, reason: str) -> None:
        seq = self.sequencer
        if seq is None:
            return
        try:
            seq.fault(reason)
            seq.poll()  # deliver the FAULT event (published like any other)
        except Exception:  # the sequencer itself is broken: the solenoid was switched off by fault()
            log.exception("could not put the sequencer in FAULT")

    # --- sequencer callbacks (main loop thread) ------------------------------------------------------------
    def _identify(self, trace: Trace, rig: Rig) -> IdentificationResult:
        """Identification (in the sequencer's worker thread) with the run's recipe rig and model,
        then wake the main loop so that the result is stored and published at once rather than at
        the next poll tick."""
        recipe = self._current_recipe
        try:
            return self._identifier(trace, recipe.rig_for(rig) if recipe is not None else rig)
        finally:
            self._wakeup.set()

    def _on_event(self, event: Event) -> None:
        self._armed_at = event.time if event.state is State.ARMED else None
        if event.state is State.ARMED:
            self._started_runs += 1
            self._capture_watch.armed()
            if event.measurement_id:
                self._run_started[event.measurement_id] = (time.monotonic(), self._accepted_source)
                if self._accepted_reply is not None:
                    self._run_reply[event.measurement_id] = self._accepted_reply
                    self._accepted_reply = None
                self._run_part[event.measurement_id] = self._accepted_part
                self._current_recipe = self._accepted_part[1]
        if event.state in (State.FAULT, State.ABORTED) and event.measurement_id \
                and event.measurement_id in self._run_started:
            self._store_failure(event)
        self._to_publishers("on_state", self._state_message(event.state.value, event.previous.value, event.reason,
                                                            event.measurement_id, event), event)
        self._refresh_live()

    def _state_message(self, state: str, previous: str, reason: str, measurement_id: str | None,
                       event: Event | None = None) -> dict[str, Any]:
        # before the sequencer's first transition: its count so far (0, so the next is 1 and no loss shows) and
        # its clock, so that every state message has the same keys
        msg: dict[str, Any] = self.public_event(event) if event is not None else {
            "transition": 0, "time": self.devices.clock.now() if self.devices is not None else None,
            "state": state, "previous": previous, "reason": reason, "measurement_id": measurement_id}
        now = self.wall_clock()
        msg.update({"device_id": self.config.device_id, "timestamp": now, "at": iso_utc(now)})
        return msg

    def public_event(self, event: Event) -> dict[str, Any]:
        """``event.to_dict()`` for whatever leaves the device (MQTT state, the web page): the
        result's values only once the store holds the result. PUBLISHING is delivered after the
        store write; when that failed (a full disk), J must not go out while it is lost here."""
        msg = event.to_dict()
        # the sequencer's count of transitions, named apart from a result's seq (which counts measurements)
        msg["transition"] = msg.pop("seq", None)
        if event.measurement is not None and event.measurement_id not in self._durable_results:
            for key in ("J", "J_std", "omega_n"):
                msg.pop(key, None)
            msg["reason"] = "the result could not be stored"
        return msg

    def _clock_scale(self) -> float:
        return self.config.simulation.time_scale if self.config.simulated else 1.0

    def _store_measurement(self, m: Measurement) -> None:
        """The sequencer's result sink: store (with the outbox row), then Modbus, then wake MQTT. Whatever fails
        before the row is written (judging, a lazy import, no descriptor left), a failed row keeps the trace and
        the failure; the error goes on to the sequencer, whose FAULT the PLC and MQTT see."""
        try:
            self._store_result(m)
        except BaseException as exc:
            if m.id not in self._durable_results:
                self._store_lost(m, exc)
            raise

    def _store_lost(self, m: Measurement, exc: BaseException) -> None:
        """A captured measurement whose result could not be stored: a failed row with its trace (always, it is
        the evidence) and what went wrong."""
        assert self.store is not None
        finished = self.wall_clock()
        self._run_started.pop(m.id, None)
        part_id, recipe = self._run_part.pop(m.id, (self.parts.part_id, self.parts.recipe))
        error = f"captured, but not stored as a result: {type(exc).__name__}: {exc}"
        if (reply := self._run_reply.pop(m.id, None)) is not None:
            reply(CommandReply("trigger", "failed", "measurement_failed", error, {"uuid": m.id}))
        try:
            result = m.result.to_dict()
        except Exception:
            result = None
        try:
            self.store.record(uuid=m.id, status="failed", trigger=m.requested_by, device_id=self.config.device_id,
                              software_version=__version__, finished_at=finished, error=error, result=result,
                              started_at=finished - (m.finished_at - m.requested_at) / self._clock_scale(),
                              rig=self.config.rig.to_dict(), config=self.config.to_dict(), trace_t=m.trace.t,
                              trace_angle=m.trace.angle, trace_meta=dict(m.trace.meta),
                              part={"part_id": part_id, "recipe": recipe.name if recipe else None,
                                    "recipe_version": recipe.version if recipe else None})
        except BaseException:
            log.exception("could not store the failed measurement %s either", m.id)
            return
        log.error("measurement %s stored as failed: %s", m.id, error)
        self._note_stored(m.id)

    def _store_result(self, m: Measurement) -> None:
        assert self.store is not None
        finished = self.wall_clock()
        armed = self._run_started.pop(m.id, (None, ""))[0]
        took = time.monotonic() - armed if armed is not None else (m.finished_at - m.requested_at) / self._clock_scale()
        started = finished - took
        cfg = self.config
        timing = m.to_dict().get("timing", {})
        part_id, recipe = self._run_part.pop(m.id, (self.parts.part_id, self.parts.recipe))
        rig = recipe.rig_for(cfg.rig) if recipe is not None else cfg.rig
        calibration = self.calibration_state(rig, finished)
        # the station's own flags, raised on the typed result before anything reads it
        raised = ((calibration is not None and calibration["due"], F.CALIBRATION_DUE),
                  (self._capture_watch.slowed(m.result.acquisition), F.CAPTURE_SLOWED))
        flags = m.result.flags + tuple(f for up, f in raised if up and f not in m.result.flags)
        typed = dataclasses.replace(m.result, flags=flags) if flags != m.result.flags else m.result
        result = typed.to_dict()
        tensor_set = self.tensor_set if recipe is not None and recipe.tensor is not None else None
        if tensor_set is not None and (tensor_set.done or tensor_set.recipe is not recipe):
            tensor_set = None  # the set ended (aborted) while this release ran: it counts for nothing
        if tensor_set is not None:
            assert recipe is not None
            part = {"part_id": part_id, "recipe": recipe.to_dict(), "release": None, "part": None, "verdict": None,
                    "calibration": calibration, "tensor_set": tensor_set.release(typed, m.id)}
        else:
            part = self.parts.release(typed, m.id, part_id, recipe, m.result, rig) | {"calibration": calibration}

        def build(uuid: str, seq: int) -> dict[str, Any]:
            return result_payload(result, uuid=uuid, seq=seq, device_id=cfg.device_id, trigger=m.requested_by,
                                  started_at=started, finished_at=finished, software_version=__version__,
                                  timing=timing, part=part)

        trace = m.trace
        try:
            stored = self.store.record(
                uuid=m.id, status="ok", trigger=m.requested_by, device_id=cfg.device_id,
                software_version=__version__, started_at=started, finished_at=finished, result=result,
                build_payload=build, rig=rig.to_dict(), config=cfg.to_dict(),
                trace_t=trace.t if cfg.store_trace else None, trace_angle=trace.angle if cfg.store_trace else None,
                trace_meta=dict(trace.meta), enqueue={p.NAME: p.OUTBOX for p in self.publishers if p.OUTBOX},
                part=_part_columns(part),
            )
        except BaseException:
            if tensor_set is not None:
                tensor_set.forget_last()
            else:
                self.parts.undo_last()  # not stored: the release does not count for the part
            raise
        self._durable_results.append(m.id)
        self._to_publishers("on_result", stored, m)
        self._note_stored(m.id)
        if (reply := self._run_reply.pop(m.id, None)) is not None:
            reply(CommandReply(V.TRIGGER, "done", data={"uuid": m.id, "seq": stored.seq}))
        log.info("measurement %s (seq %d) stored: J = %s kg·m², flags %s", m.id, stored.seq, typed.J,
                 ", ".join(typed.flags) or "none")
        if part["verdict"] is not None and recipe is not None:
            log.info("part %s (%s): %s", part_id or "(no ID)", recipe.name, part["verdict"])
            self._to_publishers("on_part_done", recipe)
        whole = part.get("part")
        check = whole.get("check_standard") if isinstance(whole, dict) else None
        if check is not None:
            # a check standard measured at the station: kept with the history `moi check-standard` reads;
            # a failed one makes the next results calibration_due (``calibration_state``)
            log.log(logging.INFO if check["passed"] else logging.WARNING, "check standard %s: E_n = %.2f (%s)",
                    check["name"], check["E_n"], "pass" if check["passed"] else "FAIL")
            try:
                self.store.record_check_standard(check | {"part_id": part_id, "measurement": m.id,
                                                          "flags": list(typed.flags)},
                                                 finished_at=finished)
            except StoreError:
                log.exception("could not store the check standard of measurement %s", m.id)
            self._calibration_checked = (-float("inf"), None, False, False)  # it may clear or raise the block
        if tensor_set is not None:
            log.info("tensor set %s: %s", tensor_set.uuid, tensor_set.instruction())
            if tensor_set.done:
                self._finish_set(tensor_set)
            self._publish_set()

    def calibration_state(self, rig: Rig, now: float) -> dict[str, Any] | None:
        """The rig's calibration as of ``now`` (Unix s): date, validity, whether it is due.

        Due also while the newest check standard (`moi check-standard`) measured since the calibration
        failed (E_n > 1): the budget no longer covers what the rig does.
        """
        cal = rig.calibration
        try:
            checks = self.store.check_standards(limit=1) if self.store is not None else []
        except StoreError:
            log.exception("could not read the check standards; the calibration state leaves them out")
            checks = []
        check = checks[0] if checks else None
        if check is not None and cal is not None:
            calibrated = _dt.datetime.combine(cal.date, _dt.time(), _dt.UTC).timestamp()
            if check["finished_at"] < calibrated:
                check = None  # a check before the calibration says nothing about it
        failed = check is not None and not check["passed"]
        if cal is None and not failed:
            return None
        today = _dt.datetime.fromtimestamp(now, _dt.UTC).date()
        until = cal.valid_until if cal is not None else None
        state: dict[str, Any] = {
            "date": cal.date.isoformat() if cal is not None else None,
            "valid_until": until.isoformat() if until else None,
            "due": (cal is not None and cal.due(today)) or failed, "stiffness": rig.stiffness,
            "stiffness_std": rig.stiffness_std}
        if check is not None:
            state["check_standard"] = {k: check.get(k) for k in ("name", "E_n", "passed", "finished_at")}
        return state

    def measure_block(self) -> dict[str, Any] | None:
        """Why no measurement may start now, for every door (button, Modbus, MQTT, Sparkplug, web), or None.

        The calibration of the rig the active recipe measures with is past its validity period, or the newest
        check standard since it failed (``calibration_state``): every result would carry calibration_due and be
        INVALID, and measuring again cannot change that. A check-standard recipe is still measured while only
        a failed check standard blocks, since its passing is what clears the block; an expired calibration
        refuses it too (a check cannot renew a calibration: ``moi calibrate`` does). A recipe whose
        ``invalid_flags`` leave out ``calibration_due`` is measured too: its parts are judged, flagged. Returns the calibration
        state, ``expired`` and ``detail``: the words every door says, with whom to call ([web] contact)."""
        recipe = self.parts.recipe
        rig = recipe.rig_for(self.config.rig) if recipe is not None else self.config.rig
        now = self.wall_clock()
        state = self.calibration_state(rig, now)
        if not state or not state["due"]:
            return None
        cal = rig.calibration
        expired = cal is not None and cal.due(_dt.datetime.fromtimestamp(now, _dt.UTC).date())
        if not expired and recipe is not None and recipe.check_standard is not None:
            return None
        if (recipe is not None and recipe.check_standard is None
                and "calibration_due" not in recipe.quality.invalid_flags):
            return None  # its quality rules judge a part with the calibration due (flagged, not INVALID): its call
        check = state.get("check_standard")
        failed = check if check is not None and not check.get("passed") else None
        contact = getattr(self.config.publishers.get("web"), "contact", None) or CONTACT
        return {"calibration": state, "expired": expired,
                "detail": calibration_words(state["valid_until"] if expired else None, failed, contact)}

    def _show_block(self, refused: bool, again: bool = False) -> None:
        """The status lamp or buzzer says the calibration refuses Measure while the appliance is IDLE (it is
        not ready), and again at each refused trigger (``again``: a buzzer beeps it once more)."""
        indicator = self.devices.indicator if self.devices is not None else None
        if indicator is None or self.sequencer is None or self.sequencer.state is not State.IDLE:
            return
        shown = getattr(indicator, "shown", None)
        try:
            if refused and (again or shown != "BLOCKED"):
                indicator.show("BLOCKED")
            elif not refused and shown == "BLOCKED":
                indicator.show("IDLE")
        except Exception:  # a status lamp must never stop the appliance
            log.exception("indicator failed to show the calibration's block")

    def _store_failure(self, event: Event) -> None:
        assert self.store is not None and event.measurement_id is not None
        armed, trigger = self._run_started.pop(event.measurement_id)
        finished = self.wall_clock()
        part_id, recipe = self._run_part.pop(event.measurement_id, (None, None))
        status = "failed" if event.state is State.FAULT else "aborted"
        if (reply := self._run_reply.pop(event.measurement_id, None)) is not None:
            reply(CommandReply(V.TRIGGER, "failed", "measurement_failed", event.reason or status,
                               {"uuid": event.measurement_id}))
        try:
            self.store.record(uuid=event.measurement_id, status=status, trigger=trigger,
                              device_id=self.config.device_id, software_version=__version__,
                              started_at=finished - (time.monotonic() - armed), finished_at=finished, error=event.reason, rig=self.config.rig.to_dict(),
                              config=self.config.to_dict(),
                              part={"part_id": part_id, "recipe": recipe.name if recipe else None,
                                    "recipe_version": recipe.version if recipe else None})
            self._note_stored(event.measurement_id)
        except ServiceError:
            log.exception("could not store the %s measurement %s", status, event.measurement_id)

    def _note_stored(self, uuid: str) -> None:
        with self._stored_cond:
            self.stored.append(uuid)
            self._stored_cond.notify_all()

    def wait_stored(self, n: int, timeout: float) -> bool:
        """Wait until ``n`` measurements were stored since start (tests, demo). True if so."""
        deadline = time.monotonic() + timeout
        with self._stored_cond:
            while len(self.stored) < n:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._stored_cond.wait(left)
        return True

    # --- live status --------------------------------------------------------------------------------------------
    def live_status(self) -> LiveStatus:
        seq = self.sequencer
        state = seq.state.value if seq is not None else "STARTING"
        fields: dict[str, Any] = {}
        for p in self.publishers:
            fields |= p.live_fields()
        fields |= self._set_registers()
        due, refused = self._calibration_due()
        return LiveStatus(
            state="STOPPING" if self._stopping else state, busy=bool(seq and seq.busy), fault=state == "FAULT",
            simulated=self.config.simulated, started=self._started_runs,
            recipe=self.parts.recipe.number if self.parts.recipe else 0,
            releases_done=(self.parts.open_part or {}).get("done", 0),
            calibration_due=due, measure_refused=refused,
            store_unwritable=self.store is not None and self.store.write_failure is not None,
            **fields,
        )

    def _calibration_due(self) -> tuple[bool, bool]:
        """Whether the active rig's calibration is due (past its validity period by the wall clock, or its check
        standard failed) and whether it refuses a trigger (``measure_block``); looked at once per
        CALIBRATION_CHECK_INTERVAL, at a change of recipe and after a check standard, not at every iteration."""
        recipe = self.parts.recipe
        now = time.monotonic()
        checked_at, checked_for, due, refused = self._calibration_checked
        if checked_for is recipe and now - checked_at < CALIBRATION_CHECK_INTERVAL:
            return due, refused
        refused = self.measure_block() is not None
        if refused:
            due = True
        else:
            rig = recipe.rig_for(self.config.rig) if recipe is not None else self.config.rig
            state = self.calibration_state(rig, self.wall_clock())
            due = bool(state and state["due"])
        self._calibration_checked = (now, recipe, due, refused)
        return due, refused

    def _set_registers(self) -> dict[str, int]:
        p = self.tensor_set.progress() if self.tensor_set is not None else None
        if p is None:
            return {}
        o = p["orientation"]
        return {"set_step": p["step"], "set_steps": p["steps"], "set_orientation": o["index"] if o else 0}

    def _refresh_live(self) -> None:
        live = self.live_status()
        self._show_block(live.measure_refused)
        if self.publishers:
            self._to_publishers("on_live", live)

    def _status_text(self) -> str:
        seq = self.sequencer
        parts = [seq.state.value.lower() if seq else "starting"]
        if self.store is not None and self.store.write_failure is not None:
            parts.append(f"result store cannot be written ({self.store.write_failure}): measurements refused")
        for p in self.publishers:
            parts += p.status()
        return "; ".join(parts)

    # --- stop -------------------------------------------------------------------------------------------------------
    def stop(self) -> None:
        """Graceful stop: finish an identification that is nearly done or abort the measurement,
        solenoid off, devices closed, in-flight MQTT publications given a moment, store closed."""
        self.notifier.stopping()
        self._stopping = True
        self._refresh_live()
        seq = self.sequencer
        if seq is not None:
            try:
                if seq.state in (State.IDENTIFYING, State.PUBLISHING):
                    # the swing is recorded: a few more seconds give a result instead of nothing
                    deadline = time.monotonic() + self.stop_grace
                    while seq.state in (State.IDENTIFYING, State.PUBLISHING) and time.monotonic() < deadline:
                        seq.poll()
                        if self.notifier.watchdog_due():
                            self.notifier.watchdog()
                        time.sleep(self.poll_interval)
                if seq.busy:
                    seq.abort("daemon stopping")
                    seq.poll()
            except Exception:  # stopping: make safe below whatever happened
                log.exception("error while finishing the measurement at stop")
            finally:
                seq.close()
        self._interrupt_set("the daemon stopped")
        self._shutdown_components()

    def _shutdown_components(self) -> None:
        # in reverse start order: those started after the devices first (the web page's handlers read the
        # store and the devices; MQTT's in-flight publications get a moment), then the devices, then
        # the early ones (the PLC sees STOPPING to the end)
        late = [p for p in self.publishers if not p.EARLY]
        early = [p for p in self.publishers if p.EARLY]
        self._stop_publishers(late)
        if self.devices is not None:
            self.devices.close()  # solenoid first
            self.devices = None
        self._stop_publishers(early)
        self.publishers = []
        if self._compiling is not None:  # a first run stopped before the kernel was compiled: the next start compiles it
            self._compiling.terminate()
            try:
                self._compiling.wait(5)
            except subprocess.TimeoutExpired:
                self._compiling.kill()
                self._compiling.wait()
            self._compiling = None
        if self.store is not None:
            self.store.close()
            self.store = None
        self._unlock_state_dir()
        self.notifier.close()


def _part_columns(part: Mapping[str, Any]) -> dict[str, Any]:
    """The store's part columns from the payload's part keys."""
    recipe, release, whole = part.get("recipe") or {}, part.get("release") or {}, part.get("part") or {}
    return {"part_id": part.get("part_id"), "part_uuid": release.get("part_uuid"), "recipe": recipe.get("name"),
            "recipe_version": recipe.get("version"), "release_index": release.get("index"),
            "releases": release.get("of"), "verdict": release.get("verdict"), "part_verdict": part.get("verdict"),
            "part_value": whole.get("mean"), "part_U": whole.get("U")}


def lock_state_dir(state: Path) -> int:
    """Take the state directory's lock (the descriptor holds it; closing it releases it). One daemon
    per state directory: a second one would take over the MQTT client id and deliver every result
    twice. The lock is the kernel's (flock): it goes with the process."""
    import fcntl
    import os

    try:
        state.mkdir(parents=True, exist_ok=True)
        fd = os.open(state / LOCK_NAME, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o640)
    except OSError as exc:
        raise StartupError(f"cannot create the lock file in {str(state)!r}: {exc.strerror}") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        other = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
        os.close(fd)
        raise StartupError(f"another moi daemon (pid {other}) runs on the state directory {str(state)!r}; "
                           "stop it first, or give this one its own state_dir") from None
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    return fd


class _Fatal(ServiceError):
    """A component thread died: the daemon stops (and systemd restarts it)."""
