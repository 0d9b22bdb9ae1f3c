"""Wiring by name, guarded: Drake ends the process at an input connected twice or a duplicate system name.
"""

from typing import TypeVar, Union, cast

from pydrake.systems.framework import DiagramBuilder, InputPort, OutputPort, System

from drake_hybrid.core.errors import ArgumentError

SystemType = TypeVar("SystemType", bound=System)


def port_label(port: Union[InputPort, OutputPort]) -> str:
    """'system.port' of an input or output port, for a message."""
    system = cast(System, port.get_system())           # pydrake's stubs: an object
    return f"'{system.get_name()}.{port.get_name()}'"


def refuse_wired(builder: DiagramBuilder, input_port: InputPort, owner: str, hint: str = "") -> None:
    """ArgumentError naming ``input_port`` (and ``hint``) if the builder already wires or exports it: Drake
    ends the process at a second Connect instead of raising."""
    if builder.IsConnectedOrExported(input_port):
        raise ArgumentError(f"{owner}: the input port {port_label(input_port)} is already connected in the "
                            f"builder{hint}; an input takes one source")


def guarded_connect(builder: DiagramBuilder, output_port: OutputPort, input_port: InputPort, owner: str) -> None:
    """``builder.Connect(output_port, input_port)`` after ``refuse_wired``."""
    refuse_wired(builder, input_port, owner)
    builder.Connect(output_port, input_port)


def unique_name(builder: DiagramBuilder, name: str, suffix: str) -> str:
    """``name``, or ``name_<suffix>`` (then ``_2``, ...) if the builder already has a system of that name:
    a diagram's systems need names of their own (Drake ends the process at Build otherwise)."""
    taken = {system.get_name() for system in builder.GetSystems()}
    candidates = [name, f"{name}_{suffix}"] + [f"{name}_{suffix}_{count}" for count in range(2, 1000)]
    return next(candidate for candidate in candidates if candidate not in taken)


def add_named(builder: DiagramBuilder, name: str, system: SystemType, robot_name: str) -> SystemType:
    """``builder.AddNamedSystem`` with ``unique_name``."""
    return cast(SystemType, builder.AddNamedSystem(unique_name(builder, name, robot_name), system))   # the same system


def port_of(system: System, name: str, kind: str, owner: str, argument: str) -> Union[InputPort, OutputPort]:
    """``system``'s input (``kind`` "input") or output port ``name``; ArgumentError naming ``argument``."""
    has = system.HasInputPort(name) if kind == "input" else system.HasOutputPort(name)
    if not has:
        ports = (system.get_input_port(i) for i in range(system.num_input_ports())) if kind == "input" else (
            system.get_output_port(i) for i in range(system.num_output_ports()))
        raise ArgumentError(f"{owner}: {argument} ('{system.get_name()}') has no {kind} port '{name}'; its {kind} "
                            f"ports: {', '.join(port.get_name() for port in ports) or 'none'}")
    return system.GetInputPort(name) if kind == "input" else system.GetOutputPort(name)
