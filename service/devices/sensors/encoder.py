"""The Modbus RTU angle encoder (``[hardware.encoder]``, ``drivers.encoder.ModbusEncoder``), and its simulated
twin: ``drivers.sim_encoder.SimEncoderServer`` on a loopback socket read by the same client the device uses."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from drivers.errors import DriverConfigError
from service.errors import ConfigError
from service.settings.defaults import MAX_ENCODER_TIME_SCALE, SIM_ENCODER_TIME_SCALE
from service.settings.schema import SensorFail, SensorTable

from .port import SensorKind

if TYPE_CHECKING:  # pragma: no cover
    from drivers.clock import Clock
    from drivers.simrig import SimRig
    from service.settings.config import Config, SimulationSettings

log = logging.getLogger("moi.hardware")

#: the simulated encoder client's reply time-out, s of real time (a scaled clock must not stretch it)
SIM_ENCODER_TIMEOUT = 0.05



def _parse(values: dict[str, Any], fail: SensorFail) -> dict[str, Any]:
    """[hardware.encoder] is the encoder driver's own settings table: the driver checks it; kept as written."""
    from drivers.encoder import EncoderConfig

    try:
        EncoderConfig.from_dict(dict(values))
    except DriverConfigError as exc:
        raise fail(None, str(exc)) from None
    return values


class Encoder(SensorKind):
    NAME = "encoder"
    LABEL = "encoder"
    MAX_TIME_SCALE = MAX_ENCODER_TIME_SCALE
    DEFAULT_TIME_SCALE = SIM_ENCODER_TIME_SCALE
    GROUPS = ("dialout",)  # the RS-485 adapters
    DEVICE_CLASSES = ("char-ttyUSB", "char-ttyACM", "char-ttyAMA", "char-ttyS")
    TIME_SCALE_REASON = ("the largest the simulated encoder keeps up with: its Modbus link answers some 500–1500 "
                         "reads per wall-clock second, and a capture needs dozens of samples per swing")
    TABLE = SensorTable(
        what="the Modbus encoder",
        doc="[hardware.encoder]: drivers.encoder.EncoderConfig (port, device_id, baudrate, parity, register, "
            "registers, counts_per_turn, direction, zero, timeout, ...)",
        needs="port, device id, register, counts per turn", parse=_parse)

    @classmethod
    def build(cls, config: Config, clock: Clock) -> Any:
        from drivers.encoder import EncoderConfig, ModbusEncoder

        hw = config.hardware
        assert hw is not None
        try:
            enc = EncoderConfig.from_dict(dict(hw.sensors.get(cls.NAME) or {}))
        except DriverConfigError as exc:
            raise ConfigError(f"{config.source}: [hardware.encoder]: {exc}") from None
        return ModbusEncoder(enc, clock)

    @classmethod
    def simulate(cls, sim: SimulationSettings, pendulum: SimRig, clock: Clock,
                 notes: list[str]) -> tuple[Any, list[Callable[[], None]]]:
        from drivers.encoder import ModbusEncoder
        from drivers.sim_encoder import SimEncoderConfig, SimEncoderServer

        bits = sim.bits or 17
        server = SimEncoderServer(pendulum.angle, clock, SimEncoderConfig(
            counts_per_turn=1 << bits, registers=1 if bits <= 16 else 2, noise_std=sim.noise,
            latency=sim.latency, drop_rate=sim.drop_rate, crc_error_rate=sim.crc_rate, glitch_rate=sim.glitch_rate,
            seed=sim.seed)).start()
        try:
            notes.append(f"simulated encoder: Modbus RTU on {server.url}, {bits} bits")
            if sim.time_scale > 1.0:
                # the round trip's jitter (tens of µs of wall time) is time_scale× longer on the simulated clock
                log.warning("simulated encoder at time_scale %g: the timestamps jitter %g× more in simulated time "
                            "than in real time; expect correlated_residual or outlier flags a real-time capture "
                            "would not raise (the default time_scale 1 keeps up)", sim.time_scale, sim.time_scale)
            # requests paced at `rate` (simulated time), as a device's client would be: back to back the
            # simulated link answers some 2000 reads/s and loads the host that dates them
            sensor = ModbusEncoder(server.encoder_config(
                timeout=SIM_ENCODER_TIMEOUT, min_interval=min(1.0 / (sim.rate * sim.time_scale), 1.0)), clock)
        except BaseException:
            server.stop()
            raise
        return sensor, [server.stop]

    @classmethod
    def health(cls, config: Config) -> list[tuple[str, bool, str]]:
        hw = config.hardware
        port = str((hw.sensors.get(cls.NAME) or {}).get("port", "")) if hw is not None else ""
        if not port or "://" in port:
            return []
        present = Path(port).exists()
        return [("encoder serial port", present, port + (" present" if present else " does not exist"))]


SENSOR = Encoder
