"""The publisher port: what the daemon knows of a way the appliance tells the plant.

A publisher (the Modbus server, the MQTT client, the web page, the OPC UA
server) is one class with ``NAME`` (its configuration table, and its name in
the logs and on the health page), a ``build(settings, appliance)`` class
method, and the hooks below; every hook has a default that does nothing, so a
publisher implements only what it publishes. ``service.publish.registry``
lists them: adding one is one subpackage (the publisher and its settings) and
one line there. The daemon holds the publishers that the configuration
enables in a list and never names one.

Hooks run on the daemon's main loop thread (``on_*``, ``live``, ``status``,
``failure``); they must hand work over and never block.
"""

from __future__ import annotations

import concurrent.futures
from typing import TYPE_CHECKING, Any, Callable, ClassVar, Mapping

if TYPE_CHECKING:  # pragma: no cover
    from firmware_host import Event, Measurement, Sequencer
    from service.core.live import LiveStatus
    from service.devices.hardware import Devices
    from service.notify import Notifier
    from service.parts.recipes import Recipe
    from service.parts.tracker import PartTracker
    from service.persistence.store import Store, StoredMeasurement
    from service.publish.replies import ReplyTo
    from service.settings.config import Config
    from service.settings.schema import Key


class Publisher:
    """The interface; a publisher subclasses it (or provides the same members)."""

    #: the configuration table it is built from, and its name
    NAME: ClassVar[str] = ""
    #: started before the devices are built (a camera or an encoder may take seconds to open)
    EARLY: ClassVar[bool] = False
    #: the store's outbox rows queued with each result, for a publisher that delivers from the durable outbox:
    #: its own rows (consumer ``NAME``), which its ``OutboxSender(consumer=NAME)`` sends and acknowledges
    OUTBOX: ClassVar[tuple[str, ...]] = ()

    @classmethod
    def build(cls, settings: Any, appliance: ApplianceView) -> Publisher:
        """The publisher for its settings (the configuration table), not yet started."""
        raise NotImplementedError

    def start(self) -> None:
        """Serve (StartupError when it cannot: an address in use, a refused credential)."""

    def stop(self) -> None:
        """Stop serving; safe twice."""

    def failure(self) -> str | None:
        """None while it works; else the sentence why the daemon must stop (a thread that died)."""
        return None

    def where(self) -> str | None:
        """Where it serves, for the log line and the systemd status at start."""
        return None

    def health(self) -> dict[str, Any] | None:
        """What the health page shows of it."""
        return None

    def capture_requests(self) -> int:
        """How many client requests it has served while the sensor was read, since it started."""
        return 0

    def live_fields(self) -> dict[str, Any]:
        """Its part of the live status (``LiveStatus`` fields)."""
        return {}

    def status(self) -> list[str]:
        """Phrases for the systemd status line."""
        return []

    def on_state(self, message: Mapping[str, Any], event: Event | None) -> None:
        """A sequencer transition (``event``; None for the daemon's own "started"), with the public message."""

    def on_live(self, live: LiveStatus) -> None:
        """The live status, refreshed every main loop iteration."""

    def on_result(self, stored: StoredMeasurement, measurement: Measurement) -> None:
        """A measurement is in the store (its outbox rows with it)."""

    def on_recipe(self, recipe: Recipe | None) -> None:
        """The active recipe changed."""

    def on_part_id(self, part_id: str | None) -> None:
        """The part ID of the next measurement changed."""

    def on_part_done(self, recipe: Recipe) -> None:
        """A part of ``recipe`` is complete (its verdict given)."""

    def on_set(self, progress: Mapping[str, Any]) -> None:
        """A tensor set's progress changed: the orientation to mount next (``TensorSet.progress`` and the
        operator's instruction)."""

    def on_tensor_set(self, record: Mapping[str, Any]) -> None:
        """A tensor set finished and is in the store (``TensorSet.to_dict``: complete with its tensor,
        failed or aborted)."""


class ApplianceView:
    """What a publisher may see of the appliance and ask of it: read-only views and the command queue."""

    def __init__(self, appliance: Any) -> None:
        self._app = appliance

    @property
    def config(self) -> Config:
        return self._app.config

    @property
    def store(self) -> Store | None:
        return self._app.store

    @property
    def sequencer(self) -> Sequencer | None:
        return self._app.sequencer

    @property
    def devices(self) -> Devices | None:
        return self._app.devices

    @property
    def parts(self) -> PartTracker:
        return self._app.parts

    @property
    def notifier(self) -> Notifier:
        return self._app.notifier

    @property
    def loop_iterations(self) -> int:
        return self._app.loop_iterations

    @property
    def last_loop_error(self) -> str | None:
        return self._app.last_loop_error

    @property
    def software_version(self) -> str:
        from service import __version__
        return __version__

    def now(self) -> float:
        """Unix time, s (the appliance's wall clock)."""
        return self._app.wall_clock()

    def live_status(self) -> LiveStatus:
        return self._app.live_status()

    def public_event(self, event: Event) -> dict[str, Any]:
        return self._app.public_event(event)

    def publisher_health(self) -> dict[str, dict[str, Any] | None]:
        """Each publisher's health under its name (None when it is off), for the health page."""
        return self._app.publisher_health()

    def command(self, name: str, source: str, data: Mapping[str, Any] | None = None,
                reply: ReplyTo | None = None) -> None:
        """Queue a command (``Appliance.command``); ``reply`` hears its outcome on the main loop thread."""
        self._app.command(name, source, data, reply)

    def call_soon(self, fn: Callable[[], Any]) -> concurrent.futures.Future:
        return self._app.call_soon(fn)

    def use_camera(self, camera: Any) -> None:
        """A camera file read again (``CameraConfig``) put to use by the sensor kind that reads it
        (``SensorKind.use_camera``): in the running sensor from its next capture and in the running configuration
        (main loop thread: ask through ``call_soon``)."""
        from service.settings import sensor_registry as sensors

        devices = self._app.devices
        kind = sensors.running(self._app.config)
        self._app.config = kind.use_camera(self._app.config, devices.sensor if devices is not None else None, camera)

    def set_progress(self) -> dict[str, Any] | None:
        """The tensor set's progress (main loop thread: ask through ``call_soon``)."""
        return self._app.set_progress()

    def study_progress(self) -> dict[str, Any] | None:
        """The Type 1 study's progress (main loop thread: ask through ``call_soon``)."""
        return self._app.study_progress()

    def calibration_state(self) -> dict[str, Any] | None:
        """The calibration of the rig the active recipe measures with, as the next result will be judged:
        date, valid_until, due (also after a failed check standard), check_standard; None without one
        (``service.parts.calibration``: the rule)."""
        return self._app.calibration_state()

    def settings_schema(self) -> Mapping[str, Mapping[str, Key]]:
        """Every table of the configuration file and its keys as declared (``service.config.appliance.SCHEMA``):
        their docs say their units and their kinds which ones name a path; the set-up page writes the running
        configuration with them."""
        return self._app.settings_schema()

    def measure_block(self) -> dict[str, Any] | None:
        """Why the calibration refuses a measurement now (``service.parts.calibration.measure_block``: the one rule
        every door uses; calibration, expired, detail), or None."""
        return self._app.measure_block()
