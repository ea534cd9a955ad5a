"""The Sparkplug B payload (protobuf) and topic namespace.

The payload is the protobuf message ``org.eclipse.tahu.protobuf.Payload`` of the Eclipse Sparkplug B
specification. Google's ``protobuf`` runtime encodes and decodes it; this module only declares the part
of the message the appliance uses (payload, metric, property set and property value, with the
specification's field numbers), so no generated code is kept in the repository. Fields the appliance
never writes (data sets, templates, metadata, extensions) are left out of the declaration: a peer that
sends them has them skipped as unknown fields.

``pysparkplug`` (a Python implementation of the same specification) is the independent decoder the
tests read these messages back with; it is not a run-time dependency because it pins paho-mqtt below 2.
"""

from __future__ import annotations

import enum
import time
from typing import Any

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

#: the topic namespace of Sparkplug B
NAMESPACE = "spBv1.0"


class DataType(enum.IntEnum):
    """The specification's metric and property data types (the ones the appliance uses, and their kin)."""

    Int8 = 1
    Int16 = 2
    Int32 = 3
    Int64 = 4
    UInt8 = 5
    UInt16 = 6
    UInt32 = 7
    UInt64 = 8
    Float = 9
    Double = 10
    Boolean = 11
    String = 12
    DateTime = 13
    Text = 14
    UUID = 15


#: the field of the value oneof that carries each data type
VALUE_FIELD: dict[DataType, str] = {
    **dict.fromkeys((DataType.Int8, DataType.Int16, DataType.Int32, DataType.UInt8, DataType.UInt16, DataType.UInt32),
                    "int_value"),
    **dict.fromkeys((DataType.Int64, DataType.UInt64, DataType.DateTime), "long_value"),
    DataType.Float: "float_value", DataType.Double: "double_value", DataType.Boolean: "boolean_value",
    **dict.fromkeys((DataType.String, DataType.Text, DataType.UUID), "string_value"),
}

_F = descriptor_pb2.FieldDescriptorProto
_OPT, _REP = _F.LABEL_OPTIONAL, _F.LABEL_REPEATED
_TYPES = {"uint32": _F.TYPE_UINT32, "uint64": _F.TYPE_UINT64, "float": _F.TYPE_FLOAT, "double": _F.TYPE_DOUBLE,
          "bool": _F.TYPE_BOOL, "string": _F.TYPE_STRING, "bytes": _F.TYPE_BYTES}
_PACKAGE = "org.eclipse.tahu.protobuf"

#: (message, [(field, number, type or nested message, repeated, in the value oneof)]), as the specification numbers them
_MESSAGES: tuple[tuple[str, tuple[tuple[str, int, str, bool, bool], ...]], ...] = (
    ("PropertyValue", (
        ("type", 1, "uint32", False, False), ("is_null", 2, "bool", False, False),
        ("int_value", 3, "uint32", False, True), ("long_value", 4, "uint64", False, True),
        ("float_value", 5, "float", False, True), ("double_value", 6, "double", False, True),
        ("boolean_value", 7, "bool", False, True), ("string_value", 8, "string", False, True),
        ("propertyset_value", 9, "PropertySet", False, True))),
    ("PropertySet", (("keys", 1, "string", True, False), ("values", 2, "PropertyValue", True, False))),
    ("Metric", (
        ("name", 1, "string", False, False), ("alias", 2, "uint64", False, False),
        ("timestamp", 3, "uint64", False, False), ("datatype", 4, "uint32", False, False),
        ("is_historical", 5, "bool", False, False), ("is_transient", 6, "bool", False, False),
        ("is_null", 7, "bool", False, False), ("properties", 9, "PropertySet", False, False),
        ("int_value", 10, "uint32", False, True), ("long_value", 11, "uint64", False, True),
        ("float_value", 12, "float", False, True), ("double_value", 13, "double", False, True),
        ("boolean_value", 14, "bool", False, True), ("string_value", 15, "string", False, True),
        ("bytes_value", 16, "bytes", False, True))),
)


def _declare() -> Any:
    """The Payload message class, from a file descriptor in a pool of its own (a peer's generated
    Sparkplug module in the same process keeps its own)."""
    f = descriptor_pb2.FileDescriptorProto(name="moi/sparkplug_b.proto", package=_PACKAGE, syntax="proto2")
    payload = f.message_type.add(name="Payload")
    for name, fields in _MESSAGES:
        msg = payload.nested_type.add(name=name)
        if any(oneof for *_, oneof in fields):
            msg.oneof_decl.add(name="value")
        for fname, number, ftype, repeated, oneof in fields:
            fd = msg.field.add(name=fname, number=number, label=_REP if repeated else _OPT)
            if ftype in _TYPES:
                fd.type = _TYPES[ftype]
            else:
                fd.type, fd.type_name = _F.TYPE_MESSAGE, f".{_PACKAGE}.Payload.{ftype}"
            if oneof:
                fd.oneof_index = 0
    for fname, number, ftype in (("timestamp", 1, "uint64"), ("seq", 3, "uint64"), ("uuid", 4, "string"),
                                 ("body", 5, "bytes")):
        payload.field.add(name=fname, number=number, label=_OPT, type=_TYPES[ftype])
    payload.field.add(name="metrics", number=2, label=_REP, type=_F.TYPE_MESSAGE,
                      type_name=f".{_PACKAGE}.Payload.Metric")
    pool = descriptor_pool.DescriptorPool()
    pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(f"{_PACKAGE}.Payload"))


#: the protobuf message class of a Sparkplug B payload
Payload = _declare()


def now_ms() -> int:
    """Unix time in ms, as Sparkplug timestamps are."""
    return int(time.time() * 1000)


def set_value(metric: Any, datatype: DataType, value: Any) -> None:
    """Write ``value`` into ``metric``'s value field for its data type (None: ``is_null``)."""
    if value is None:
        metric.is_null = True
        return
    field = VALUE_FIELD[datatype]
    if datatype in (DataType.Int8, DataType.Int16, DataType.Int32):
        value = int(value) & 0xFFFFFFFF  # two's complement in the uint32 field, as the specification says
    elif datatype == DataType.Int64:
        value = int(value) & 0xFFFFFFFFFFFFFFFF
    setattr(metric, field, value)


def get_value(metric: Any, datatype: DataType) -> Any:
    """The value of ``metric`` read as ``datatype`` (None when null or absent)."""
    if metric.is_null or metric.WhichOneof("value") is None:
        return None
    value = getattr(metric, VALUE_FIELD[datatype])
    bits = {DataType.Int8: 8, DataType.Int16: 16, DataType.Int32: 32, DataType.Int64: 64}.get(datatype)
    if bits is not None:
        value &= (1 << bits) - 1
        if value >= 1 << (bits - 1):
            value -= 1 << bits
    return value


def add_metric(payload: Any, name: str | None, datatype: DataType, value: Any, *, alias: int | None = None,
               timestamp: int | None = None, unit: str | None = None, historical: bool = False) -> Any:
    """Append a metric to ``payload``; ``unit`` becomes the ``engUnit`` property (as SCADA reads it)."""
    m = payload.metrics.add()
    if name is not None:
        m.name = name
    if alias is not None:
        m.alias = alias
    if timestamp is not None:
        m.timestamp = timestamp
    m.datatype = int(datatype)
    if historical:
        m.is_historical = True
    if unit is not None:
        m.properties.keys.append("engUnit")
        pv = m.properties.values.add()
        pv.type = int(DataType.String)
        pv.string_value = unit
    set_value(m, datatype, value)
    return m


def topic(group: str, message_type: str, edge_node: str, device: str | None = None) -> str:
    """``spBv1.0/<group>/<type>/<edge node>[/<device>]``."""
    return f"{NAMESPACE}/{group}/{message_type}/{edge_node}" + (f"/{device}" if device else "")


def state_topic(host_id: str) -> str:
    """The retained STATE topic of a Sparkplug host application (specification 3.0)."""
    return f"{NAMESPACE}/STATE/{host_id}"
