"""The in-process simulated sensor (``[simulation] sensor = "direct"``): ``drivers.SimulatedAngleSensor`` samples
the simulated pendulum at ``rate``, with the encoder's noise and resolution; faster than the encoder's link, for
tests. There is no such device."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

from .port import SensorKind

if TYPE_CHECKING:  # pragma: no cover
    from drivers.clock import Clock
    from drivers.simrig import SimRig
    from service.settings.config import SimulationSettings


class Direct(SensorKind):
    NAME = "direct"
    LABEL = "encoder"  # it stands for the encoder: the angle, sampled
    HARDWARE = False

    @classmethod
    def simulate(cls, sim: SimulationSettings, pendulum: SimRig, clock: Clock,
                 notes: list[str]) -> tuple[Any, list[Callable[[], None]]]:
        from drivers.sensor import SimulatedAngleSensor

        sensor = SimulatedAngleSensor(pendulum.angle, clock, rate=sim.rate, noise_std=sim.noise,
                                      quantisation_bits=sim.bits or None, seed=sim.seed, source="encoder")
        notes.append(f"simulated sensor: in process at {sim.rate:g} Hz")
        return sensor, []


SENSOR = Direct
