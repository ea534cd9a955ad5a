"""The appliance as a machine in the address space, an instance of the types ``model`` installs: its
Identification, the two state machines (MachineryItemState, MachineryOperationMode) and ResultManagement with
its methods and LatestResult, whose structures' fields are also variables of their own. ``add_machine``
returns the nodes the server writes."""

from __future__ import annotations

import math
from datetime import UTC, datetime
from typing import Any, Callable, Mapping

from asyncua import Node, Server, ua
from asyncua.common.instantiate_util import instantiate

from .model import CONTENT_FIELDS, META_COMPONENTS, Model, node_id, rereference, variable, with_unit

#: the value of a variable before the first result (OPC UA has no null scalar of these types)
EMPTY: dict[ua.VariantType, Any] = {ua.VariantType.String: "", ua.VariantType.Int32: 0, ua.VariantType.UInt32: 0,
                                    ua.VariantType.Boolean: False, ua.VariantType.Double: math.nan,
                                    ua.VariantType.DateTime: datetime(1970, 1, 1, tzinfo=UTC)}
#: the variant type of a ns=0 DataType of CONTENT_FIELDS
VTYPES: dict[int, ua.VariantType] = {ua.ObjectIds.UInt32: ua.VariantType.UInt32,
                                     ua.ObjectIds.Double: ua.VariantType.Double,
                                     ua.ObjectIds.String: ua.VariantType.String}


class _Builder:
    """The server, the installed model and the device id every node of the machine is named after."""

    def __init__(self, server: Server, model: Model, device_id: str) -> None:
        self.server, self.model, self.device_id = server, model, device_id

    def nid(self, name: str) -> ua.NodeId:
        return ua.NodeId(ua.String(f"{self.device_id}.{name}"), ua.Int16(self.model.moi))

    async def typed(self, parent: Node, name: str, bname: ua.QualifiedName, typedef: ua.NodeId,
                    optional: bool = True) -> Node:
        """An instance of an ObjectType with the children its modelling rules ask for."""
        return (await instantiate(parent, self.server.get_node(typedef), self.nid(name), bname,
                                  instantiate_optional=optional))[0]


async def add_machine(server: Server, model: Model, device_id: str, identity: Mapping[str, Any],
                      methods: Mapping[str, Callable[..., Any]], *, unacknowledged: int) -> dict[str, Node]:
    """Add the machine under Objects/Machines: ``identity``, the Identification's values by browse name;
    ``methods``, ResultManagement's methods by name; ``unacknowledged``, the results awaiting an
    acknowledgement now. Returns the nodes by the names the server writes them under."""
    b = _Builder(server, model, device_id)
    mach = model.machinery
    nodes: dict[str, Node] = {}
    machines = await server.nodes.objects.add_folder(node_id(1001, mach), ua.QualifiedName("Machines", mach))
    machine = await machines.add_object(b.nid("Machine"), ua.QualifiedName(device_id, model.moi))
    ident = await _identification(b, machine, identity, nodes)
    blocks = await machine.add_folder(b.nid("MachineryBuildingBlocks"),
                                      ua.QualifiedName("MachineryBuildingBlocks", mach))
    await blocks.add_reference(ident, ua.ObjectIds.HasAddIn, forward=True, bidirectional=False)
    await _state_machines(b, blocks, nodes)
    results = await _result_management(b, blocks, methods, nodes)
    nodes["unacknowledged"] = await results.add_variable(
        b.nid("Results.UnacknowledgedCount"), ua.QualifiedName("UnacknowledgedCount", model.moi),
        ua.Variant(unacknowledged, ua.VariantType.UInt32))
    await _latest_result(b, results, nodes)
    return nodes


async def _identification(b: _Builder, machine: Node, identity: Mapping[str, Any], nodes: dict[str, Node]) -> Node:
    di = b.model.di
    ident = await b.typed(machine, "Identification", ua.QualifiedName("Identification", di),
                          b.model.nodes["MachineIdentificationType"])
    await rereference(machine, ident, ua.ObjectIds.HasAddIn)
    for name, value in identity.items():
        node = await ident.get_child(f"{di}:{name}")
        await node.write_value(value)
        nodes[name] = node
    return ident


async def _state_machines(b: _Builder, blocks: Node, nodes: dict[str, Node]) -> None:
    mach = b.model.machinery
    for key, bname, typedef in (("item", "MachineryItemState", "MachineryItemState_StateMachineType"),
                                ("mode", "MachineryOperationMode", "MachineryOperationModeStateMachineType")):
        sm = await b.typed(blocks, bname, ua.QualifiedName(bname, mach), b.model.nodes[typedef], optional=False)
        await rereference(blocks, sm, ua.ObjectIds.HasAddIn)
        nodes[f"{key}.state"] = await sm.get_child("0:CurrentState")
        nodes[f"{key}.id"] = await sm.get_child(["0:CurrentState", "0:Id"])


async def _result_management(b: _Builder, blocks: Node, methods: Mapping[str, Callable[..., Any]],
                             nodes: dict[str, Node]) -> Node:
    """ResultManagement, an event notifier, with its methods linked; returns its Results folder."""
    res = b.model.result
    rm = await b.typed(blocks, "ResultManagement", ua.QualifiedName("ResultManagement", res),
                       b.model.nodes["ResultManagementType"])
    await rereference(blocks, rm, ua.ObjectIds.HasAddIn)
    await rm.write_attribute(ua.AttributeIds.EventNotifier, ua.DataValue(ua.Variant(1, ua.VariantType.Byte)))
    for name, callback in methods.items():
        b.server.link_method(await rm.get_child(f"{res}:{name}"), callback)
    nodes["result_management"] = rm
    return await rm.get_child(f"{res}:Results")


async def _latest_result(b: _Builder, results: Node, nodes: dict[str, Node]) -> None:
    res, idx, t, nid = b.model.result, b.model.moi, b.model.nodes, b.nid
    # a variable of ResultType, made by hand: asyncua's instantiation of a VariableType copies attributes
    # a type has not (and logs each)
    latest = await variable(results, nid("Results.LatestResult"), ua.QualifiedName("LatestResult", res),
                            ua.Variant(None, ua.VariantType.Null), t["ResultDataType"], t["ResultType"])
    structured = ua.ObjectIds.HasStructuredComponent
    meta = await variable(latest, nid("Results.LatestResult.ResultMetaData"), ua.QualifiedName("ResultMetaData", res),
                          ua.Variant(None, ua.VariantType.Null), t["ResultMetaDataType"], reference=structured)
    content = await variable(latest, nid("Results.LatestResult.ResultContent"),
                             ua.QualifiedName("ResultContent", res), ua.Variant([], ua.VariantType.ExtensionObject),
                             node_id(ua.ObjectIds.BaseDataType), array=True, reference=structured)
    nodes.update({"latest": latest, "latest.meta": meta, "latest.content": content})
    # the structures' fields the appliance fills, also as variables of their own (for clients that read
    # scalars): ResultMetaData's structured components [Result], ResultContent's InertiaResultDataType [moi],
    # the physical values of AnalogUnitType with their EngineeringUnits
    for name, (_, vtype) in META_COMPONENTS.items():
        nodes[f"meta.{name}"] = await variable(
            meta, nid(f"Results.LatestResult.ResultMetaData.{name}"), ua.QualifiedName(name, res),
            ua.Variant(EMPTY[vtype], vtype), node_id(vtype.value), reference=structured)
    for name, dt, array, _, unit in CONTENT_FIELDS:
        vtype = VTYPES[dt]
        qname, cid = ua.QualifiedName(name, idx), nid(f"Results.LatestResult.ResultContent.{name}")
        empty = ua.Variant([] if array else EMPTY[vtype], vtype)
        nodes[f"content.{name}"] = await (
            with_unit(content, cid, qname, empty, unit) if unit is not None
            else variable(content, cid, qname, empty, node_id(dt), array=array))
