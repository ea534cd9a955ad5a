"""Device drivers: one small interface per device, real and mock side by side.

    Solenoid          release solenoid, GPIO output, hard maximum on-time   (drivers.solenoid)
    PushButton        operator button, GPIO input                           (drivers.button)
    Indicator         optional status LED / buzzer                          (drivers.indicator)
    ModbusEncoder     RS-485 Modbus RTU absolute encoder, sampling thread   (drivers.encoder)
    SimEncoderServer  simulated encoder: a real pymodbus RTU server         (drivers.sim_encoder)
    SimRig            simulated rig coupling the mocks to the physics       (drivers.simrig)
    FrameSource       file-backed camera: video file or image folder        (drivers.video_file)
    AngleSensor       what the sequencer captures from                      (drivers.sensor)
    CameraAngleSensor a Camera as an AngleSensor (tracking, yaw fit)        (drivers.camera_sensor)
    Clock             MonotonicClock, ManualClock, ScaledClock              (drivers.clock)

Real or mock is chosen in one place, ``drivers.backend.pin_factory`` (a
backend setting or ``GPIOZERO_PIN_FACTORY=mock``) for GPIO, and by the port
(``/dev/ttyUSB0`` or ``socket://127.0.0.1:PORT`` of the simulated encoder)
for the encoder. Cameras live in ``drivers.camera`` and ``drivers.camera_sensor``
(separate modules: they pull in OpenCV, which the encoder path does not need).
"""

from .clock import Clock, ManualClock, MonotonicClock, ScaledClock
from .errors import DeviceFault, DriverConfigError, DriverError, EncoderFault, SensorFault
from .sensor import AngleSensor, AngleSource, SimulatedAngleSensor

__all__ = [
    "Clock", "ManualClock", "MonotonicClock", "ScaledClock",
    "DriverError", "DriverConfigError", "DeviceFault", "SensorFault", "EncoderFault",
    "AngleSensor", "AngleSource", "SimulatedAngleSensor",
]
