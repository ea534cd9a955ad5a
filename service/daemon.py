"""The appliance daemon: sequencer, result store, the publishers and systemd, in one main loop.

Threads and who owns what:

* the main loop (``Appliance.run``, the caller's thread) polls the sequencer
  every ``poll_interval`` s, executes the commands queued by the button and
  every publisher's door (``service.dispatch``), refreshes the live status
  every publisher gets and pings the systemd watchdog, only after an iteration
  that completed (a hung loop therefore gets the daemon restarted by systemd);
* the sequencer calls back on the main loop's thread: state events (handed to
  every publisher) and the result sink (``service.recording``), which judges
  the release for its part, stores the measurement and its outbox rows in one
  SQLite transaction, then hands the stored result to every publisher; nothing
  is published before the store has it;
* the publishers (``service.publish.port``; the registry,
  ``service.publish.registry``, lists them) run in their own threads and only
  enqueue commands / acknowledgements; the daemon holds them in a list and
  never names one but to hand a test or a tool the running one by its name.

Only ``run``'s loop catches broadly: an unexpected error becomes a FAULT of
the sequencer (solenoid off), published like any state; a component thread
that died ends the daemon with status 3 so that systemd restarts it.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import logging
import queue
import subprocess
import sys
import threading
import time
from typing import Any, Callable, Mapping

from firmware_host import Event, Sequencer, State
from measurement import IdentificationResult, Options, Rig, Trace, identify
from measurement.integrator import is_compiled
from measurement.reproducibility import for_release
from service.config.appliance import SCHEMA, whom_to_call
from service.core import vocabulary as V
from service.core.live import LiveStatus
from service.devices.hardware import Devices, build_devices
from service.parts import calibration as calibration_rule
from service.parts.gauge_study import StudyDesk
from service.parts.recipes import Recipe, RecipeBook
from service.parts.set_desk import SetDesk
from service.parts.tensor_set import TensorSet
from service.parts.tracker import PartTracker
from service.persistence.state_dir import lock_state_dir, open_store, unlock_state_dir
from service.persistence.store import Store
from service.publish import registry
from service.publish.payload import iso_utc
from service.publish.port import ApplianceView, Publisher
from service.publish.replies import CONTACT, ReplyTo
from service.settings.config import Config
from service.sources.repeats import RigHistory

from . import __version__
from .contention import CaptureWatch
from .dispatch import Dispatcher
from .errors import ServiceError, StoreError
from .notify import Notifier
from .recording import Recorder

log = logging.getLogger("moi.daemon")

#: exit statuses of ``run``
EXIT_OK = 0
EXIT_RUNTIME_FAILURE = 3

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
        self._identifier = identifier or (lambda trace, rig: identify(trace, rig, self.identification_options(rig)))
        self._devices = devices
        self.devices: Devices | None = None
        self.store: Store | None = None
        self.history: RigHistory | None = None  # the rig's repeat releases in the store, once it is open
        self.publishers: list[Publisher] = []  # started, in start order
        self.sequencer: Sequencer | None = None
        self._commands: queue.SimpleQueue[tuple[str, str, Mapping[str, Any] | None, ReplyTo | None]] = queue.SimpleQueue()
        self._calls: queue.SimpleQueue[tuple[Callable[[], Any], concurrent.futures.Future]] = queue.SimpleQueue()
        self._wakeup = threading.Event()
        self._stop = threading.Event()
        self._compiling: subprocess.Popen | None = None  # the integrator compiled on a first run
        self._started_runs = 0
        self.capture_watch = CaptureWatch(lambda: sum(p.capture_requests() for p in self.publishers))
        self.parts = PartTracker(config.recipes or RecipeBook(None), config.active_recipe)
        self._current_recipe: Recipe | None = None
        self.sets = SetDesk(config.state_dir, config.device_id, lambda: self.store, self.to_publishers,
                            self._refresh_live, wall_clock)
        self.studies = StudyDesk(config.state_dir, lambda: self.store, wall_clock)
        self._last_status = ""
        self.loop_iterations = 0
        self.last_loop_error: str | None = None
        self.recorder = Recorder(self)
        self.dispatcher = Dispatcher(self)
        self.exit_status = EXIT_OK
        self._stopping = False
        self._lock_fd: int | None = None
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
            self.store = open_store(self.config.state_dir, self.wall_clock)
            self.history = RigHistory(self.store)
            view = ApplianceView(self)
            enabled = [(entry.load(), settings) for entry in registry.PUBLISHERS
                       if (settings := cfg.publishers.get(entry.name)) is not None]
            self._start_publishers([(kind, s) for kind, s in enabled if kind.EARLY], view)
            self.devices = self._devices or build_devices(cfg)
            d = self.devices
            # the button is wired through the command queue like the other sources, so every
            # trigger is logged and executed the same way on the main loop
            self.sequencer = Sequencer(clock=d.clock, solenoid=d.solenoid, sensor=d.sensor, rig=cfg.rig,
                                       sink=self.recorder.sink, config=cfg.sequencer,
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
        self.sets.recover()
        self.studies.recover()
        self.open_set()  # a tensor recipe active from the configuration: its set waits for the first release
        self._refresh_live()
        self.to_publishers("on_state", self._state_message("IDLE", "IDLE", "daemon started", None), None)
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

    def to_publishers(self, hook: str, *args: Any) -> None:
        """Call ``hook`` of every publisher (main loop thread; hooks never block)."""
        for p in self.publishers:
            getattr(p, hook)(*args)

    def publisher(self, name: str) -> Publisher | None:
        """The running publisher of configuration table ``name``, or None."""
        return next((p for p in self.publishers if name == p.NAME), None)

    # one property per publisher of the registry (a test holds the two together), for tests and tools: the running
    # publisher, None when off (typed Any: the daemon imports no publisher's module)
    @property
    def modbus(self) -> Any:
        return self.publisher("modbus")

    @property
    def web(self) -> Any:
        return self.publisher("web")

    @property
    def mqtt(self) -> Any:
        return self.publisher("mqtt")

    @property
    def opcua(self) -> Any:
        return self.publisher("opcua")

    @property
    def sparkplug(self) -> Any:
        return self.publisher("sparkplug")

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
            unlock_state_dir(self._lock_fd)
            self._lock_fd = None

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
        return min(self.poll_interval, max(0.0, due / self.clock_scale()))

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
            outcome = self.dispatcher.execute(name, source, data, reply)
            if reply is not None:
                reply(outcome)

    # --- the guided tensor set (main loop thread; ``SetDesk``) ------------------------------------------------
    @property
    def tensor_set(self) -> TensorSet | None:
        """The guided set of a tensor recipe (open or just finished)."""
        return self.sets.current

    def open_set(self) -> None:
        """A tensor set for the active recipe and part, when it declares one (``SetDesk.open``)."""
        self.sets.open(self.parts.recipe, self.config.rig, self.parts.part_id)
        self.studies.selected(self.parts.recipe)  # a Type 1 study ends with its recipe

    def set_progress(self) -> dict[str, Any] | None:
        """The tensor set's progress with the operator's instruction (None: no set)."""
        return self.sets.progress()

    def study_progress(self) -> dict[str, Any] | None:
        """The Type 1 study's progress (``StudyDesk.progress``; None: none since start)."""
        return self.studies.progress()

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

    def identification_options(self, rig: Rig) -> Options:
        """The configuration's identification options with ``rig``'s scatter between releases pooled from the store's
        repeat releases since its calibration (any thread); else its calibration's figure, else the default (``for_release``)."""
        history = self.history.reproducibility(rig) if self.history is not None else None
        return dataclasses.replace(self.config.identification, reproducibility=for_release(history, rig.reproducibility))

    def _on_event(self, event: Event) -> None:
        self._armed_at = event.time if event.state is State.ARMED else None
        if event.state is State.ARMED:
            self._started_runs += 1
            self.capture_watch.armed()
            if event.measurement_id:
                source, reply, part = self.dispatcher.accepted
                self.recorder.armed(event.measurement_id, source, reply, part)
                self.dispatcher.accepted = (source, None, part)  # one run hears the reply
                self._current_recipe = part[1]
        if event.state in (State.FAULT, State.ABORTED) and self.recorder.running(event.measurement_id):
            self.recorder.failed(event)
        self.to_publishers("on_state", self._state_message(event.state.value, event.previous.value, event.reason,
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
        if event.measurement is not None and not self.recorder.durable(event.measurement_id):
            for key in ("J", "J_std", "omega_n"):
                msg.pop(key, None)
            msg["reason"] = "the result could not be stored"
        return msg

    def clock_scale(self) -> float:
        """Simulated seconds per real second (1 on hardware)."""
        return self.config.simulation.time_scale if self.config.simulated else 1.0

    # --- the calibration rule's inputs (the rule: service.parts.calibration) ----------------------------------
    def newest_checks(self) -> list[dict[str, Any]]:
        """The newest stored check standard ([] without one, or when the store cannot be read: said in the log)."""
        try:
            return self.store.check_standards(limit=1) if self.store is not None else []
        except StoreError:
            log.exception("could not read the check standards; the calibration state leaves them out")
            return []

    def _active_rig(self) -> Rig:
        recipe = self.parts.recipe
        return recipe.rig_for(self.config.rig) if recipe is not None else self.config.rig

    def settings_schema(self) -> Mapping[str, Mapping[str, Any]]:
        """Every table of the configuration file and its keys as declared (what the set-up page words them with)."""
        return SCHEMA

    def calibration_state(self) -> dict[str, Any] | None:
        """The calibration of the active recipe's rig as the next result will be judged (``calibration_state``)."""
        return calibration_rule.calibration_state(self._active_rig(), self.newest_checks(), self.wall_clock())

    def contact(self) -> str:  # whom every door says to call ([web] contact): a calibration's block, a FAULT
        return whom_to_call(self.config) or CONTACT

    def measure_block(self) -> dict[str, Any] | None:
        """Why no measurement may start now, for every door (``calibration.measure_block``) with ``contact()``."""
        return calibration_rule.measure_block(self._active_rig(), self.parts.recipe, self.newest_checks(), self.wall_clock(),
                                              self.contact(), self.config.require_calibration)

    def show_block(self, refused: bool, again: bool = False) -> None:
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

    @property
    def stored(self) -> list[str]:
        """UUIDs stored since start (ok, failed, aborted), in order."""
        return self.recorder.stored

    def wait_stored(self, n: int, timeout: float) -> bool:
        """Wait until ``n`` measurements were stored since start (tests, demo). True if so."""
        return self.recorder.wait_stored(n, timeout)

    def calibration_changed(self) -> None:
        """A check standard was stored: the live status looks at the calibration again at once."""
        self._calibration_checked = (-float("inf"), None, False, False)

    # --- live status --------------------------------------------------------------------------------------------
    def live_status(self) -> LiveStatus:
        seq = self.sequencer
        state = seq.state.value if seq is not None else "STARTING"
        fields: dict[str, Any] = {}
        for p in self.publishers:
            fields |= p.live_fields()
        fields |= self.sets.registers()
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
            state = self.calibration_state()
            due = bool(state and state["due"])
        self._calibration_checked = (now, recipe, due, refused)
        return due, refused

    def _refresh_live(self) -> None:
        live = self.live_status()
        self.show_block(live.measure_refused)
        if self.publishers:
            self.to_publishers("on_live", live)

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
        self.sets.interrupt("the daemon stopped")
        self.studies.interrupt("the daemon stopped")
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


class _Fatal(ServiceError):
    """A component thread died: the daemon stops (and systemd restarts it)."""
