"""The live status: what the appliance is doing now, refreshed by the daemon every main loop iteration.

The daemon builds it (``Appliance.live_status``) and hands it to every publisher (``Publisher.on_live``); the
Modbus map encodes it in its live registers and status bits, the web page and MQTT show it.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class LiveStatus:
    """The appliance's state now (not a result: no snapshot protocol protects it)."""

    state: str | None = "STARTING"
    busy: bool = False
    fault: bool = False
    mqtt_connected: bool = False
    simulated: bool = False
    outbox_pending: int = 0
    started: int = 0
    recipe: int = 0          # active recipe number (0: none)
    releases_done: int = 0   # releases of the part in progress
    set_step: int = 0        # tensor set: the step to measure now (1-based; 0: no set)
    set_steps: int = 0       # tensor set: orientations in the plan
    set_orientation: int = 0  # tensor set: number of the orientation to mount now (1-based; 0: none)
    calibration_due: bool = False   # the rig's calibration is past its validity period
    measure_refused: bool = False   # the calibration refuses a trigger now (``service.parts.calibration.measure_block``)
    store_unwritable: bool = False  # the result store cannot be written: measurements are refused
