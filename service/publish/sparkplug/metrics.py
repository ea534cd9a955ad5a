"""The appliance's metrics as a Sparkplug device: every name, data type, engineering unit and alias.

One table for the birth certificates (each metric with its name, alias, type and ``engUnit``), the result
DDATA (read from the published result payload, ``service.publish.payload``), the live state and the
commands a host may write (DCMD). Aliases are the table's order: stable across births and releases of
the same table.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Mapping

from service.parts.outcome import PartOutcome

from .payload import DataType

#: the node's own metrics (NBIRTH): bdSeq is sent by name only, as the specification wants it
BD_SEQ = "bdSeq"
REBIRTH = "Node Control/Rebirth"
SOFTWARE_VERSION = "Properties/Software Version"


@dataclass(frozen=True)
class DeviceMetric:
    """One metric of the device. read: its value from a result payload (result metrics only)."""

    name: str
    datatype: DataType
    unit: str | None = None
    read: Callable[[Mapping[str, Any]], Any] | None = None


def _key(key: str) -> Callable[[Mapping[str, Any]], Any]:
    return lambda p: p.get(key)


def finished_ms(p: Mapping[str, Any]) -> int | None:
    """The result's finish (its payload's ``timestamp``, Unix s) in ms."""
    t = p.get("timestamp")
    return int(round(float(t) * 1000)) if t is not None else None


#: published with every result (DDATA), in this order
RESULT: tuple[DeviceMetric, ...] = (
    DeviceMetric("Result/UUID", DataType.UUID, read=_key("uuid")),
    DeviceMetric("Result/Sequence", DataType.UInt64, read=_key("seq")),
    DeviceMetric("Result/Finished", DataType.DateTime, read=finished_ms),
    DeviceMetric("Result/J", DataType.Double, "kg·m²", _key("J")),
    DeviceMetric("Result/J_U", DataType.Double, "kg·m²", _key("J_U")),
    DeviceMetric("Result/J_std", DataType.Double, "kg·m²", _key("J_std")),
    DeviceMetric("Result/omega_n", DataType.Double, "rad/s", _key("omega_n")),
    DeviceMetric("Result/damping_ratio", DataType.Double, "1", _key("damping_ratio")),
    DeviceMetric("Result/Flags", DataType.String, read=lambda p: ",".join(p.get("flags") or ())),
    # Int64, not UInt32: the Sparkplug 3.0 proto carries a UInt32 in int_value, Tahu's JavaScript codec and Ignition
    # before 2022 read it from long_value; an Int64 is long_value in every codec (the 32 bits fit without a sign)
    DeviceMetric("Result/Flag Bits", DataType.Int64, read=_key("flag_bits")),
    DeviceMetric("Result/Verdict", DataType.String, read=lambda p: PartOutcome.from_dict(p).shown_verdict or ""),
    DeviceMetric("Result/Part ID", DataType.String, read=lambda p: p.get("part_id") or ""),
    DeviceMetric("Result/Trigger", DataType.String, read=_key("trigger")),
)

#: the live state (DDATA when it changes)
STATE = DeviceMetric("Status/State", DataType.String)
BUSY = DeviceMetric("Status/Busy", DataType.Boolean)
FAULT = DeviceMetric("Status/Fault", DataType.Boolean)
LIVE: tuple[DeviceMetric, ...] = (STATE, BUSY, FAULT)

#: what a host may write (DCMD) → the appliance's command and how the value becomes its data
COMMANDS: dict[str, tuple[DeviceMetric, str]] = {
    "Command/Measure": (DeviceMetric("Command/Measure", DataType.Boolean), "trigger"),
    "Command/Abort": (DeviceMetric("Command/Abort", DataType.Boolean), "abort"),
    "Command/Recipe": (DeviceMetric("Command/Recipe", DataType.String), "recipe"),
    "Command/Part ID": (DeviceMetric("Command/Part ID", DataType.String), "part_id"),
}
#: the outcome of the last command (the JSON a reply on MQTT carries), DDATA after each
REPLY = DeviceMetric("Command/Reply", DataType.String)

#: every device metric, in alias order
DEVICE: tuple[DeviceMetric, ...] = RESULT + LIVE + tuple(m for m, _ in COMMANDS.values()) + (REPLY,)
#: node metrics with an alias (bdSeq has none)
NODE: tuple[DeviceMetric, ...] = (DeviceMetric(REBIRTH, DataType.Boolean), DeviceMetric(SOFTWARE_VERSION, DataType.String))

#: alias of each metric by name: node metrics first, then the device's (unique within the edge node)
ALIAS: dict[str, int] = {m.name: i for i, m in enumerate(NODE + DEVICE, start=1)}
BY_ALIAS: dict[int, str] = {a: name for name, a in ALIAS.items()}
