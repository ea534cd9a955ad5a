"""The companion specifications' types the appliance uses, modelled in the specifications' namespaces with their
NodeIds, browse names, supertypes and (for the structures) field layout and binary encoding NodeIds:

- OPC 10000-100 Devices (DI): FunctionalGroupType, the Identification properties' browse names;
- OPC 40001-1 Machinery 1.03: Machines, MachineryItemIdentificationType, MachineIdentificationType,
  MachineryItemState_StateMachineType and MachineryOperationModeStateMachineType with their states;
- OPC 40001-101 Machinery Result Transfer 1.01: ResultEvaluationEnum, ProcessingTimesDataType,
  ResultMetaDataType, ResultDataType, ResultType, ResultManagementType (GetResultById, GetLatestResult,
  AcknowledgeResults, Results) and the abstract ResultReadyEventType;
- the appliance's own (``urn:moi:opcua``): InertiaResultDataType, the content of a result, and
  InertiaResultReadyEventType, the concrete event it raises.

Why modelled and not loaded from the published NodeSet2 files: docs/opcua.md. What is left out is what the
appliance does not implement (optional members: interfaces, transitions, GetResultIdListFiltered,
ReleaseResultHandle, ResultTransfer); a client that reads a type definition, decodes a ResultDataType by its
encoding NodeId or subscribes to ResultReadyEventType finds what the specifications define. Every node that
is not one of the specifications' gets a string NodeId in ``urn:moi:opcua``, so none can take a NodeId the
specifications assign.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

from asyncua import Node, Server, ua
from asyncua.common.manage_nodes import create_data_type
from asyncua.common.structures104 import new_enum

NS_DI = "http://opcfoundation.org/UA/DI/"
NS_MACHINERY = "http://opcfoundation.org/UA/Machinery/"
NS_RESULT = "http://opcfoundation.org/UA/Machinery/Result/"
NS_MOI = "urn:moi:opcua"

#: MachineryItemState_StateMachineType's states: NodeId (Machinery) and StateNumber
ITEM_STATE_NODES: dict[str, tuple[int, int]] = {
    "NotAvailable": (5005, 0), "OutOfService": (5004, 1), "NotExecuting": (5007, 2), "Executing": (5006, 3)}
#: MachineryOperationModeStateMachineType's states: NodeId (Machinery) and StateNumber
OPERATION_MODE_NODES: dict[str, tuple[int, int]] = {
    "None": (5024, 0), "Maintenance": (5025, 1), "Setup": (5027, 2), "Processing": (5026, 3)}

#: ResultEvaluationEnum (OPC 40001-101)
RESULT_EVALUATION: dict[str, int] = {"Undefined": 0, "OK": 1, "NotOK": 2, "NotDecidable": 3}

#: ResultMetaDataType's fields in the specification's order (the optional-field mask bits follow it):
#: name, DataType (a ns=0 id, or the name of a type modelled here), array, optional
_META_FIELDS: tuple[tuple[str, int | str, bool, bool], ...] = (
    ("ResultId", ua.ObjectIds.TrimmedString, False, False),
    ("HasTransferableDataOnFile", ua.ObjectIds.Boolean, False, True),
    ("IsPartial", ua.ObjectIds.Boolean, False, True),
    ("IsSimulated", ua.ObjectIds.Boolean, False, True),
    ("ResultState", ua.ObjectIds.Int32, False, True),
    ("StepId", ua.ObjectIds.TrimmedString, False, True),
    ("PartId", ua.ObjectIds.TrimmedString, False, True),
    ("ExternalRecipeId", ua.ObjectIds.TrimmedString, False, True),
    ("InternalRecipeId", ua.ObjectIds.TrimmedString, False, True),
    ("ProductId", ua.ObjectIds.TrimmedString, False, True),
    ("ExternalConfigurationId", ua.ObjectIds.TrimmedString, False, True),
    ("InternalConfigurationId", ua.ObjectIds.TrimmedString, False, True),
    ("JobId", ua.ObjectIds.TrimmedString, False, True),
    ("CreationTime", ua.ObjectIds.UtcTime, False, True),
    ("ProcessingTimes", "ProcessingTimesDataType", False, True),
    ("ResultUri", ua.ObjectIds.UriString, True, True),
    ("ResultEvaluation", "ResultEvaluationEnum", False, True),
    ("ResultEvaluationCode", ua.ObjectIds.Int64, False, True),
    ("ResultEvaluationDetails", ua.ObjectIds.LocalizedText, False, True),
    ("FileFormat", ua.ObjectIds.String, True, True),
)
#: the ResultMetaData fields the appliance fills, shown also as variables of their own under
#: LatestResult/ResultMetaData (the specification's structured components) for clients that read scalars
META_COMPONENTS: dict[str, tuple[int, ua.VariantType]] = {
    "ResultId": (6012, ua.VariantType.String), "IsSimulated": (6015, ua.VariantType.Boolean),
    "ResultState": (6016, ua.VariantType.Int32), "PartId": (6018, ua.VariantType.String),
    "ExternalRecipeId": (6019, ua.VariantType.String), "ProductId": (6021, ua.VariantType.String),
    "CreationTime": (6025, ua.VariantType.DateTime), "ResultEvaluation": (6028, ua.VariantType.Int32),
}

#: the units of the physical values, by symbol: the UNECE Recommendation 20 common code (which OPC 10000-8 makes the
#: EUInformation's UnitId) and the unit's name
UNITS: dict[str, tuple[str, str]] = {
    "kg·m²": ("B32", "kilogram metre squared"),
    "rad/s": ("2A", "radian per second"),
    "1": ("C62", "one"),
}
#: the namespace of the UNECE codes in EUInformation (OPC 10000-8)
UNECE_URI = "http://www.opcfoundation.org/UA/units/un/cefact"

#: InertiaResultDataType, a result's content (urn:moi:opcua): name, DataType, array, its meaning, and the unit
#: of a physical value (a key of UNITS; None for the others)
CONTENT_FIELDS: tuple[tuple[str, int, bool, str, str | None], ...] = (
    ("SequenceNumber", ua.ObjectIds.UInt32, False, "the result's sequence number (MQTT seq, Modbus seq)", None),
    ("J", ua.ObjectIds.Double, False, "the moment of inertia, kg·m²", "kg·m²"),
    ("J_U", ua.ObjectIds.Double, False, "the expanded uncertainty of J where the result carries one, kg·m² "
                                         "(NaN otherwise)", "kg·m²"),
    ("J_u", ua.ObjectIds.Double, False, "the combined standard uncertainty of J (fit ⊕ calibration ⊕ model "
                                         "form), kg·m²", "kg·m²"),
    ("U", ua.ObjectIds.Double, False, "the verdict's expanded uncertainty (with a recipe), kg·m²; NaN without",
     "kg·m²"),
    ("omega_n", ua.ObjectIds.Double, False, "the undamped natural angular frequency ω_n, rad/s", "rad/s"),
    ("damping_ratio", ua.ObjectIds.Double, False, "the damping ratio ζ (1)", "1"),
    ("Flags", ua.ObjectIds.String, True, "the result's quality flags", None),
    ("Verdict", ua.ObjectIds.String, False, "OK, NOK, INVALID or empty (no recipe)", None),
)


def eu_information(symbol: str) -> ua.EUInformation:
    """The EngineeringUnits of a value in the unit ``symbol`` (a key of UNITS): its UNECE code as UnitId, one
    byte per character (OPC 10000-8), the symbol as DisplayName."""
    code, name = UNITS[symbol]
    unit_id = 0
    for char in code:
        unit_id = unit_id << 8 | ord(char)
    return ua.EUInformation(NamespaceUri=UNECE_URI, UnitId=unit_id, DisplayName=ua.LocalizedText(symbol),
                            Description=ua.LocalizedText(name))


#: the methods of ResultManagementType the appliance implements: NodeId (Result), inputs, outputs
#: (name, DataType, array, description)
_Arg = tuple[str, Any, bool, str]
METHODS: dict[str, tuple[int, tuple[_Arg, ...], tuple[_Arg, ...]]] = {
    "GetResultById": (7005, (
        ("ResultId", ua.ObjectIds.TrimmedString, False, "the result's ResultId (its UUID)"),
        ("Timeout", ua.ObjectIds.Int32, False, "how long the client needs the result, ms (a hint)"),
    ), (
        ("ResultHandle", ua.ObjectIds.Handle, False, "0: ReleaseResultHandle is not supported"),
        ("Result", "ResultDataType", False, "the result"),
        ("Error", ua.ObjectIds.Int32, False, "0: OK"),
    )),
    "GetLatestResult": (7008, (
        ("Timeout", ua.ObjectIds.Int32, False, "wait at most this long for a result when none exists yet, ms"),
    ), (
        ("ResultHandle", ua.ObjectIds.Handle, False, "0: ReleaseResultHandle is not supported"),
        ("Result", "ResultDataType", False, "the result"),
        ("Error", ua.ObjectIds.Int32, False, "0: OK"),
    )),
    "AcknowledgeResults": (7009, (
        ("ResultIds", ua.ObjectIds.TrimmedString, True, "the ResultIds of the results acknowledged"),
    ), (
        ("ErrorPerResultId", ua.ObjectIds.Int32, True, "empty when Error is 0; else per ResultId: 0 OK, "
                                                       "-1 unknown ResultId, -2 awaits no acknowledgement (acknowledged already)"),
        ("Error", ua.ObjectIds.Int32, False, "0: all acknowledged; -1: not all"),
    )),
}


@dataclass
class Model:
    """The namespace indexes and the NodeIds the server fills in, once installed."""

    di: int
    machinery: int
    result: int
    moi: int
    nodes: dict[str, ua.NodeId] = field(default_factory=dict)

    def state_id(self, machine: str, state: str) -> ua.NodeId:
        table = ITEM_STATE_NODES if machine == "item" else OPERATION_MODE_NODES
        return node_id(table[state][0], self.machinery)


def node_id(identifier: int | str, ns: int = 0) -> ua.NodeId:
    """A NodeId from a number or a string in namespace ``ns`` (asyncua's types, for mypy)."""
    ident: Any = ua.Int32(identifier) if isinstance(identifier, int) else ua.String(identifier)
    return ua.NodeId(ident, ua.Int16(ns))


def _qn(name: str, ns: int) -> ua.QualifiedName:
    return ua.QualifiedName(name, ns)


async def rereference(parent: Node, child: Node, new: int) -> None:
    """Link ``child`` to ``parent`` by reference type ``new`` instead of the one asyncua chose (HasComponent,
    Organizes under a folder); the specifications use HasAddIn and HasStructuredComponent, subtypes of
    HasComponent, so a browse for HasComponent and its subtypes finds the child either way."""
    for ref in await parent.get_references(ua.ObjectIds.HierarchicalReferences, ua.BrowseDirection.Forward):
        if ref.NodeId == child.nodeid and ref.ReferenceTypeId != node_id(new):
            await parent.delete_reference(child, ref.ReferenceTypeId, forward=True, bidirectional=True)
    await parent.add_reference(child, new, forward=True, bidirectional=True)


async def _object_type(parent: Node, nodeid: ua.NodeId, name: str, abstract: bool = False) -> Node:
    t = await parent.add_object_type(nodeid, _qn(name, nodeid.NamespaceIndex))
    if abstract:
        await t.write_attribute(ua.AttributeIds.IsAbstract, ua.DataValue(ua.Variant(True, ua.VariantType.Boolean)))
    return t


async def _add(parent: Node, nodeid: ua.NodeId, qname: ua.QualifiedName, nodeclass: ua.NodeClass, reference: int,
               typedef: ua.NodeId, attrs: Any) -> Node:
    """A node added with its type definition (asyncua's helpers give an encoding none and a variable
    BaseDataVariableType, and a later retype leaves the parent's browse result naming the old type)."""
    item = ua.AddNodesItem()
    item.RequestedNewNodeId = nodeid
    item.BrowseName = qname
    item.NodeClass = nodeclass
    item.ParentNodeId = parent.nodeid
    item.ReferenceTypeId = node_id(reference)
    item.TypeDefinition = typedef
    attrs.DisplayName = ua.LocalizedText(qname.Name)
    attrs.Description = ua.LocalizedText(qname.Name)
    item.NodeAttributes = attrs
    result = (await parent.session.add_nodes([item]))[0]
    result.StatusCode.check()
    return Node(parent.session, result.AddedNodeId)


async def variable(parent: Node, nodeid: ua.NodeId, qname: ua.QualifiedName, value: ua.Variant, datatype: ua.NodeId,
                   typedef: ua.NodeId | int = ua.ObjectIds.BaseDataVariableType, *, array: bool = False,
                   reference: int = ua.ObjectIds.HasComponent) -> Node:
    """A read-only variable of the VariableType ``typedef``."""
    attrs = ua.VariableAttributes()
    attrs.DataType = datatype
    attrs.Value = value
    attrs.ValueRank = ua.ValueRank.OneDimension if array else ua.ValueRank.Scalar
    attrs.ArrayDimensions = [0] if array else []
    attrs.AccessLevel = attrs.UserAccessLevel = ua.AccessLevel.CurrentRead.mask
    attrs.WriteMask = attrs.UserWriteMask = 0
    return await _add(parent, nodeid, qname, ua.NodeClass.Variable, reference,
                      typedef if isinstance(typedef, ua.NodeId) else node_id(typedef), attrs)


async def with_unit(parent: Node, nodeid: ua.NodeId, qname: ua.QualifiedName, value: ua.Variant, symbol: str) -> Node:
    """A Double variable of AnalogUnitType with its EngineeringUnits (OPC 10000-8), in the unit ``symbol``."""
    v = await variable(parent, nodeid, qname, value, node_id(ua.ObjectIds.Double), ua.ObjectIds.AnalogUnitType)
    await variable(v, ua.NodeId(ua.String(str(nodeid.Identifier) + ".EngineeringUnits"), nodeid.NamespaceIndex),
                   _qn("EngineeringUnits", 0), ua.Variant(eu_information(symbol), ua.VariantType.ExtensionObject),
                   node_id(ua.ObjectIds.EUInformation), ua.ObjectIds.PropertyType, reference=ua.ObjectIds.HasProperty)
    return v


async def _states(server: Server, model: Model, machine_type: Node, table: dict[str, tuple[int, int]]) -> None:
    """The states of a state machine type: objects of StateType with their StateNumber (no modelling rule:
    they belong to the type, as in the specification)."""
    for name, (nid, number) in table.items():
        s = await _add(machine_type, node_id(nid, model.machinery), _qn(name, model.machinery), ua.NodeClass.Object,
                       ua.ObjectIds.HasComponent, node_id(ua.ObjectIds.StateType), ua.ObjectAttributes())
        await s.add_property(node_id(f"types.{name}.StateNumber", model.moi), _qn("StateNumber", 0),
                             ua.Variant(number, ua.VariantType.UInt32))


def _field(name: str, datatype: ua.NodeId, array: bool = False, optional: bool = False,
           description: str = "") -> ua.StructureField:
    f = ua.StructureField()
    f.Name = name
    f.DataType = datatype
    f.ValueRank = 1 if array else -1
    f.ArrayDimensions = [0] if array else []
    f.IsOptional = optional
    f.Description = ua.LocalizedText(description)
    return f


async def _structure(server: Server, nodeid: ua.NodeId, encoding: ua.NodeId, name: str,
                     fields: list[ua.StructureField], kind: ua.StructureType) -> Node:
    """A structured DataType with the given NodeId and Default Binary encoding NodeId (asyncua's ``new_struct``
    picks its own encoding NodeId; a client that knows the specification decodes by the encoding's)."""
    dtype = await create_data_type(server.nodes.base_structure_type, nodeid, _qn(name, nodeid.NamespaceIndex))
    enc = await _add(dtype, encoding, ua.QualifiedName("Default Binary", 0), ua.NodeClass.Object,
                     ua.ObjectIds.HasEncoding, node_id(ua.ObjectIds.DataTypeEncodingType), ua.ObjectAttributes())
    sdef = ua.StructureDefinition()
    sdef.BaseDataType = server.nodes.base_structure_type.nodeid
    sdef.StructureType = kind
    sdef.Fields = fields
    sdef.DefaultEncodingId = enc.nodeid
    await dtype.write_data_type_definition(sdef)
    return dtype


@dataclass
class ResultDataType:
    """ResultDataType encoded as OPC 10000-6 (5.2.7) encodes a StructureWithSubtypedValues: ResultMetaData, a
    field that allows subtypes, travels as an ExtensionObject (the NodeId of its encoding, then its body), and
    no optional-field mask precedes the fields. asyncua 2.1's class made from the definition writes
    ResultMetaData inline (it drops the field's AllowSubtypes), which a stack that follows the definition
    cannot decode (node-opcua: "decodeNodeId: unknown encoding_byte")."""

    data_type: ClassVar[ua.NodeId]
    ResultMetaData: ua.ExtensionObject = field(default_factory=ua.ExtensionObject)  # a ResultMetaDataType
    ResultContent: list[ua.Variant] = field(default_factory=list)


def register_result_data_type(model: Model) -> type[ResultDataType]:
    """Make ``ResultDataType`` asyncua's class of the ResultDataType (for encoding and decoding; after
    ``load_data_type_definitions``, which made the other)."""
    data_type, encoding = node_id(3008, model.result), node_id(5008, model.result)
    ResultDataType.data_type = data_type
    ua.register_extension_object("ResultDataType", encoding, ResultDataType, data_type)
    # register_extension_object leaves ua's attribute to the first class of the name
    ua.ResultDataType = ResultDataType  # type: ignore[attr-defined]
    return ResultDataType


def argument(name: str, datatype: ua.NodeId, array: bool, description: str) -> ua.Argument:
    a = ua.Argument()
    a.Name = name
    a.DataType = datatype
    a.ValueRank = 1 if array else -1
    a.ArrayDimensions = [0] if array else []
    a.Description = ua.LocalizedText(description)
    return a


async def install(server: Server) -> Model:
    """Register the namespaces and add the types (before the server starts; a few ms)."""
    model = Model(di=await server.register_namespace(NS_DI), machinery=await server.register_namespace(NS_MACHINERY),
                  result=await server.register_namespace(NS_RESULT), moi=await server.register_namespace(NS_MOI))
    await _identification_types(server, model)
    await _state_machine_types(server, model)
    named = await _result_data_types(server, model)
    await _result_type(server, model)
    rm_type = await _result_management_type(server, model, named)
    await _result_ready_event_types(server, model, rm_type)
    return model


async def _identification_types(server: Server, model: Model) -> None:
    """DI and Machinery: the machine's identification."""
    di, mach = model.di, model.machinery
    functional_group = await _object_type(server.get_node(ua.ObjectIds.FolderType), node_id(1005, di),
                                          "FunctionalGroupType")
    item_ident = await _object_type(functional_group, node_id(1004, mach), "MachineryItemIdentificationType",
                                    abstract=True)
    for nid, name, vtype, mandatory in ((6002, "Manufacturer", ua.VariantType.LocalizedText, True),
                                        (6003, "SerialNumber", ua.VariantType.String, True),
                                        (6008, "Model", ua.VariantType.LocalizedText, False),
                                        (6011, "SoftwareRevision", ua.VariantType.String, False),
                                        (6001, "ProductInstanceUri", ua.VariantType.String, False)):
        empty = ua.LocalizedText("") if vtype is ua.VariantType.LocalizedText else ""
        p = await item_ident.add_property(node_id(nid, mach), _qn(name, di), ua.Variant(empty, vtype))
        await p.set_modelling_rule(mandatory)
    machine_ident = await _object_type(item_ident, node_id(1012, mach), "MachineIdentificationType")
    p = await machine_ident.add_property(node_id(6015, mach), _qn("ProductInstanceUri", di), "")
    await p.set_modelling_rule(True)
    model.nodes["MachineIdentificationType"] = machine_ident.nodeid


async def _state_machine_types(server: Server, model: Model) -> None:
    """Machinery: the two state machines."""
    mach = model.machinery
    fsm = server.get_node(ua.ObjectIds.FiniteStateMachineType)
    item_sm = await _object_type(fsm, node_id(1002, mach), "MachineryItemState_StateMachineType")
    await _states(server, model, item_sm, ITEM_STATE_NODES)
    mode_sm = await _object_type(fsm, node_id(1008, mach), "MachineryOperationModeStateMachineType")
    await _states(server, model, mode_sm, OPERATION_MODE_NODES)
    model.nodes["MachineryItemState_StateMachineType"] = item_sm.nodeid
    model.nodes["MachineryOperationModeStateMachineType"] = mode_sm.nodeid


async def _result_data_types(server: Server, model: Model) -> dict[str, ua.NodeId]:
    """Result Transfer's data types and the appliance's InertiaResultDataType; returns the NodeIds of those
    the method arguments name."""
    res, moi = model.result, model.moi
    evaluation = await new_enum(server, node_id(3002, res), _qn("ResultEvaluationEnum", res),
                                list(RESULT_EVALUATION))
    times = await _structure(server, node_id(3006, res), node_id(5003, res), "ProcessingTimesDataType", [
        _field("StartTime", node_id(ua.ObjectIds.UtcTime)), _field("EndTime", node_id(ua.ObjectIds.UtcTime)),
        _field("AcquisitionDuration", node_id(ua.ObjectIds.Duration), optional=True),
        _field("ProcessingDuration", node_id(ua.ObjectIds.Duration), optional=True),
    ], ua.StructureType.StructureWithOptionalFields)
    named = {"ResultEvaluationEnum": evaluation.nodeid, "ProcessingTimesDataType": times.nodeid}
    meta = await _structure(server, node_id(3007, res), node_id(5005, res), "ResultMetaDataType", [
        _field(name, named[dt] if isinstance(dt, str) else node_id(dt), array, optional)
        for name, dt, array, optional in _META_FIELDS], ua.StructureType.StructureWithOptionalFields)
    # ResultMetaData allows subtypes (it travels as an ExtensionObject); ResultContent is BaseDataType[]
    result_dt = await _structure(server, node_id(3008, res), node_id(5008, res), "ResultDataType", [
        _field("ResultMetaData", meta.nodeid, optional=True),
        _field("ResultContent", node_id(ua.ObjectIds.BaseDataType), array=True),
    ], ua.StructureType.StructureWithSubtypedValues)
    content_dt = await _structure(server, node_id("InertiaResultDataType", moi),
                                  node_id("InertiaResultDataType.DefaultBinary", moi), "InertiaResultDataType",
                                  [_field(name, node_id(dt), array, description=doc)
                                   for name, dt, array, doc, _ in CONTENT_FIELDS], ua.StructureType.Structure)
    named["ResultDataType"] = result_dt.nodeid
    model.nodes.update(ResultEvaluationEnum=evaluation.nodeid, ResultMetaDataType=meta.nodeid,
                       ResultDataType=result_dt.nodeid, InertiaResultDataType=content_dt.nodeid,
                       ProcessingTimesDataType=times.nodeid)
    return named


async def _result_type(server: Server, model: Model) -> None:
    """Result Transfer: ResultType, the variable type of a result."""
    res, n = model.result, model.nodes
    result_type = await server.get_node(ua.ObjectIds.BaseDataVariableType).add_variable_type(
        node_id(2001, res), _qn("ResultType", res), n["ResultDataType"])
    rm_meta = await result_type.add_variable(node_id(6009, res), _qn("ResultMetaData", res),
                                             ua.Variant(None, ua.VariantType.Null), datatype=n["ResultMetaDataType"])
    rm_content = await result_type.add_variable(node_id(6010, res), _qn("ResultContent", res),
                                                ua.Variant([], ua.VariantType.Variant),
                                                datatype=node_id(ua.ObjectIds.BaseDataType))
    await rm_content.write_value_rank(1)
    for child, mandatory in ((rm_meta, True), (rm_content, False)):
        await child.set_modelling_rule(mandatory)
        await rereference(result_type, child, ua.ObjectIds.HasStructuredComponent)
    n["ResultType"] = result_type.nodeid


async def _result_management_type(server: Server, model: Model, named: dict[str, ua.NodeId]) -> Node:
    """Result Transfer: ResultManagementType with its methods (their arguments typed by ``named``) and its
    Results folder."""
    res, moi = model.result, model.moi
    rm_type = await _object_type(server.nodes.base_object_type, node_id(1004, res), "ResultManagementType")
    for name, (nid, inputs, outputs) in METHODS.items():
        def args(table: tuple[_Arg, ...]) -> list[ua.Argument]:
            return [argument(a, named[dt] if isinstance(dt, str) else node_id(dt), arr, doc)
                    for a, dt, arr, doc in table]
        method = await rm_type.add_method(node_id(nid, res), _qn(name, res), None)
        await method.set_modelling_rule(False)
        for kind, table in (("InputArguments", inputs), ("OutputArguments", outputs)):
            # added here, not by add_method: it would give them NodeIds of its choosing in the Result namespace
            prop = await method.add_property(node_id(f"types.{name}.{kind}", moi), _qn(kind, 0),
                                             ua.Variant(args(table), ua.VariantType.ExtensionObject),
                                             datatype=node_id(ua.ObjectIds.Argument))
            await prop.write_value_rank(1)
            await prop.set_modelling_rule(True)
    results = await rm_type.add_folder(node_id(5011, res), _qn("Results", res))
    await results.set_modelling_rule(False)
    model.nodes["ResultManagementType"] = rm_type.nodeid
    return rm_type


async def _result_ready_event_types(server: Server, model: Model, rm_type: Node) -> None:
    """Result Transfer's ResultReadyEventType, generated by ``rm_type``, and the appliance's subtype."""
    res, moi, n = model.result, model.moi, model.nodes
    ready = await _object_type(server.get_node(ua.ObjectIds.BaseEventType), node_id(1002, res),
                               "ResultReadyEventType", abstract=True)
    ev_result = await variable(ready, node_id(6032, res), _qn("Result", res), ua.Variant(None, ua.VariantType.Null),
                               n["ResultDataType"], n["ResultType"])
    await ev_result.set_modelling_rule(True)
    await rm_type.add_reference(ready.nodeid, ua.ObjectIds.GeneratesEvent, forward=True, bidirectional=False)
    inertia_ready = await _object_type(ready, node_id("InertiaResultReadyEventType", moi),
                                       "InertiaResultReadyEventType")
    n.update(ResultReadyEventType=ready.nodeid, InertiaResultReadyEventType=inertia_ready.nodeid)
