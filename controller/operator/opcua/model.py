"""The OPC UA address space: the OPC Foundation's NodeSets (DI, Machinery, IA, ISA-95 job
control, Machinery Jobs, Machine Tools) loaded as published, one MachineToolType instantiated
under Objects/Machines, and the few variables the companion model has no place for (axis
positions, the program's line and hash, its start and run time) in a namespace of ours."""

from __future__ import annotations

import gzip
import logging
from dataclasses import dataclass, field
from importlib import resources
from typing import Any

from asyncua import Node, Server, ua
from asyncua.common.instantiate_util import instantiate

MT_URI = "http://opcfoundation.org/UA/MachineTool/"
MACHINERY_URI = "http://opcfoundation.org/UA/Machinery/"
DI_URI = "http://opcfoundation.org/UA/DI/"
IA_URI = "http://opcfoundation.org/UA/IA/"
OWN_URI = "urn:phcnc:opcua"  # positions, line, hash, times: not in the companion model

# In dependency order; MachineTool needs every one before it.
NODESETS = ("opc.ua.di.nodeset2.xml.gz", "opc.ua.machinery.nodeset2.xml.gz",
            "opc.ua.ia.nodeset2.xml.gz", "opc.ua.isa95-jobcontrol.nodeset2.xml.gz",
            "opc.ua.machinery.jobs.nodeset2.xml.gz", "opc.ua.machinetool.nodeset2.xml.gz")
MACHINE_TOOL_TYPE = 13  # ns=MachineTool;i=13 MachineToolType
CHANNEL_MONITORING_TYPE = 16
NOTIFICATION_EVENT_TYPE = 35
MACHINES_FOLDER = 1001  # ns=Machinery;i=1001 Objects/Machines
# Parts of MachineToolType a controller of an X-Y table or a small mill has nothing behind:
# left out rather than shown empty (a dashboard would show them as present).
UNUSED = (("0:FileSystem",), ("{MT}:Equipment",), ("{MT}:Notification", "{MT}:Prognoses"),
          ("{MA}:MachineryBuildingBlocks", "{JOBS}:JobManagement"))


@dataclass
class StateMachine:
    """A finite state machine instance: its CurrentState, Id and Number, and its states."""

    current: Node
    current_id: Node
    current_number: Node | None
    states: dict[str, tuple[ua.NodeId, int]]


@dataclass
class Model:
    """Handles on every node the bridge writes."""

    server: Server
    machine: Node
    ns: dict[str, int]
    variables: dict[str, Node] = field(default_factory=dict)
    machines: dict[str, StateMachine] = field(default_factory=dict)
    twins: dict[str, StateMachine] = field(default_factory=dict)  # the building blocks' copies
    also: dict[str, Node] = field(default_factory=dict)  # a variable's copy, written with it
    channel: Node | None = None
    messages: Node | None = None


async def load_nodesets(server: Server) -> None:
    """Import the companion NodeSets shipped with the package (gzip-compressed, unchanged).
    Not strict: asyncua cannot build the Python classes of three Machinery Jobs structures
    (an OptionSet field), which nothing here uses; their nodes are still imported."""
    quiet = logging.getLogger("asyncua")
    level = quiet.level
    quiet.setLevel(logging.CRITICAL)
    folder = resources.files("controller.operator.opcua").joinpath("nodesets")
    for name in NODESETS:
        text = gzip.decompress(folder.joinpath(name).read_bytes()).decode("utf-8")
        await server.import_xml(xmlstring=text, strict_mode=False)
    quiet.setLevel(level)


async def namespaces(server: Server) -> dict[str, int]:
    own = await server.register_namespace(OWN_URI)
    ns = {"OWN": own}
    for key, uri in (("MT", MT_URI), ("MA", MACHINERY_URI), ("DI", DI_URI), ("IA", IA_URI),
                     ("JOBS", MACHINERY_URI + "Jobs/")):
        ns[key] = await server.get_namespace_index(uri)
    return ns


def qualified(path: tuple[str, ...], ns: dict[str, int]) -> list[str]:
    """("{MT}:Monitoring",) -> ["7:Monitoring"]: browse names with the indexes of this server."""
    out = []
    for part in path:
        for key, index in ns.items():
            part = part.replace("{" + key + "}", str(index))
        out.append(part)
    return out


async def build(server: Server, name: str, axes: tuple[str, ...]) -> Model:
    """The machine under Objects/Machines, with the parts that fit, every value empty."""
    await load_nodesets(server)
    ns = await namespaces(server)
    machines = server.get_node(ua.NodeId(MACHINES_FOLDER, ns["MA"]))
    mtt = server.get_node(ua.NodeId(MACHINE_TOOL_TYPE, ns["MT"]))
    machine = (await instantiate(machines, mtt, bname=ua.QualifiedName(name, ns["OWN"]),
                                 dname=ua.LocalizedText(name)))[0]
    model = Model(server, machine, ns)
    for path in UNUSED:
        await _delete(machine, qualified(path, ns))
    await _identification(model)
    await _monitoring(model, axes)
    await _production(model)
    model.messages = await machine.get_child(qualified(("{MT}:Notification", "{MT}:Messages"),
                                                       ns))
    await model.messages.write_attribute(ua.AttributeIds.EventNotifier, ua.DataValue(
        ua.Variant(1, ua.VariantType.Byte)))
    return model


async def _delete(machine: Node, path: list[str]) -> None:
    try:
        node = await machine.get_child(path)
    except ua.UaError:
        return
    await node.delete(recursive=True)


async def child(model: Model, *path: str) -> Node:
    return await model.machine.get_child(qualified(path, model.ns))


async def _identification(model: Model) -> None:
    ident = await child(model, "{DI}:Identification")
    own = model.ns["DI"]
    for key in ("Manufacturer", "SerialNumber", "ProductInstanceUri"):
        model.variables[key] = await ident.get_child(f"{own}:{key}")
    mine = model.ns["OWN"]
    model.variables["Model"] = await ident.add_property(
        ua.NodeId(0, mine), ua.QualifiedName("Model", own), ua.LocalizedText(""),
        ua.VariantType.LocalizedText)
    model.variables["SoftwareRevision"] = await ident.add_property(
        ua.NodeId(0, mine), ua.QualifiedName("SoftwareRevision", own), "", ua.VariantType.String)


async def _monitoring(model: Model, axes: tuple[str, ...]) -> None:
    mt = await child(model, "{MT}:Monitoring", "{MT}:MachineTool")
    model.variables["OperationMode"] = await mt.get_child(f"{model.ns['MT']}:OperationMode")
    model.variables["PowerOnDuration"] = await mt.get_child(qualified(
        ("{DI}:OperationCounters", "{DI}:PowerOnDuration"), model.ns))
    # Machinery's building blocks hold a second copy (asyncua instantiates both): a Machinery
    # client reads them there, a Machine Tools one under Monitoring; both are written.
    blocks = await child(model, "{MA}:MachineryBuildingBlocks")
    for key, name in (("ItemState", "MachineryItemState"),
                      ("OperationMode", "MachineryOperationMode")):
        model.machines[key] = await state_machine(
            model, await mt.get_child(f"{model.ns['MA']}:{name}"))
        model.twins[key] = await state_machine(
            model, await blocks.get_child(f"{model.ns['MA']}:{name}"))
    model.also["PowerOnDuration"] = await blocks.get_child(qualified(
        ("{DI}:OperationCounters", "{DI}:PowerOnDuration"), model.ns))
    monitoring = await child(model, "{MT}:Monitoring")
    channel_type = model.server.get_node(ua.NodeId(CHANNEL_MONITORING_TYPE, model.ns["MT"]))
    channel = (await instantiate(monitoring, channel_type,
                                 bname=ua.QualifiedName("Channel1", model.ns["OWN"]),
                                 dname=ua.LocalizedText("Channel1"),
                                 instantiate_optional=False))[0]
    model.channel = channel
    mt_ns = model.ns["MT"]
    for key in ("Name", "ChannelState", "ChannelMode", "FeedOverride"):
        model.variables[key] = await channel.get_child(f"{mt_ns}:{key}")
    own = model.ns["OWN"]
    for axis in axes:
        model.variables[f"Position{axis.upper()}"] = await _own_variable(
            channel, own, f"ActualPosition{axis.upper()}", 0.0, ua.VariantType.Double,
            f"{axis.upper()} axis, machine coordinates, mm (the encoder)")
    model.variables["FeedRate"] = await _own_variable(
        channel, own, "ActualFeedrate", 0.0, ua.VariantType.Double, "path feed, mm/s")


async def _production(model: Model) -> None:
    program = await child(model, "{MT}:Production", "{MT}:ActiveProgram")
    mt, own = model.ns["MT"], model.ns["OWN"]
    model.variables["ProgramName"] = await program.get_child(f"{mt}:Name")
    model.variables["NumberInList"] = await program.get_child("0:NumberInList")
    model.machines["Program"] = await state_machine(model, await program.get_child(f"{mt}:State"))
    model.variables["JobIdentifier"] = await program.add_property(
        ua.NodeId(0, own), ua.QualifiedName("JobIdentifier", mt), "", ua.VariantType.String)
    model.variables["Line"] = await _own_variable(
        program, own, "LineNumber", 0, ua.VariantType.UInt32, "the program line being run")
    model.variables["Hash"] = await _own_variable(
        program, own, "ProgramHash", "", ua.VariantType.String, "SHA-256 of the program text")
    model.variables["StartTime"] = await _own_variable(
        program, own, "StartTime", None, ua.VariantType.DateTime, "when its motion began")
    model.variables["RunTime"] = await _own_variable(
        program, own, "RunTime", 0.0, ua.VariantType.Double, "seconds since its motion began")


async def _own_variable(parent: Node, ns: int, name: str, value: Any, vtype: ua.VariantType,
                        description: str) -> Node:
    node = await parent.add_variable(ns, name, value, vtype)
    await node.write_attribute(ua.AttributeIds.Description, ua.DataValue(
        ua.Variant(ua.LocalizedText(description), ua.VariantType.LocalizedText)))
    return node


async def state_machine(model: Model, node: Node) -> StateMachine:
    """A state machine instance and the states its type defines (name -> NodeId, number)."""
    current = await node.get_child("0:CurrentState")
    current_id = await current.get_child("0:Id")
    try:
        number = await current.get_child("0:Number")
    except ua.UaError:
        number = await current.add_property(ua.NodeId(0, model.ns["OWN"]),
                                            ua.QualifiedName("Number", 0), 0,
                                            ua.VariantType.UInt32)
    type_node = model.server.get_node(await node.read_type_definition())
    states: dict[str, tuple[ua.NodeId, int]] = {}
    state_types = {ua.NodeId(ua.ObjectIds.StateType), ua.NodeId(ua.ObjectIds.InitialStateType)}
    for candidate in await type_node.get_children(refs=ua.ObjectIds.HasComponent):
        if await candidate.read_type_definition() not in state_types:
            continue
        name = (await candidate.read_browse_name()).Name
        value = await (await candidate.get_child("0:StateNumber")).read_value()
        states[name] = (candidate.nodeid, int(value))
    return StateMachine(current, current_id, number, states)
