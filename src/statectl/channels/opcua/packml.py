"""PackML companion naming (OPC 30050) for devices whose file declares ``profile: packml``.

Rules:
1. The names below live in the PackML namespace, ``http://opcfoundation.org/UA/PackML/``,
   registered on the server when a PackML device is served; node ids stay statectl's.
2. Machines are named as OPC 30050 names them: the device's top machine
   ``BaseStateMachine``, the sub-state machine of ``Cleared`` ``MachineState`` and
   the one of ``Running`` ``ExecuteState``; each is an instance of an object type
   with the companion's name (``PackMLBaseStateMachineType``, ...), a subtype of
   statectl's state machine type (so of ``FiniteStateMachineType``). Other machines
   keep statectl's names.
3. State numbers are the table's ``number`` column (the profile's PackML numbers),
   through :func:`statectl.channels.opcua.space.layout`: ``CurrentState/Number`` of a PackML
   unit in Execute reads 6.
4. Each PackML command the device has (Abort, Clear, Hold, Reset, Start, Stop,
   Suspend, Unhold, Unsuspend) is a method of every PackML machine holding a state
   the command leaves, named as the companion names it, with no arguments: it posts
   the event and returns Good when the unit took a transition, ``BadInvalidState``
   when the event changed nothing in its state, ``BadResourceUnavailable`` when it
   was not accepted (a full queue). Calling needs the configured user, as every
   method does, on the machine that holds it (else ``BadMethodInvalid``). The device
   object's own statectl methods stay as they are.
5. A ``PackMLObjects`` folder under ``Objects`` organizes every PackML device object,
   where the companion's clients look for units.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from statectl.channels.opcua.space import Layout
from statectl.kernel.model import Chart
from statectl.kernel.semantics import Outcome

__all__ = ["PACKML_URI", "PROFILE", "PackmlNaming", "PackmlSpace", "naming", "status_of"]

PACKML_URI = "http://opcfoundation.org/UA/PackML/"
PROFILE = "packml"
#: The commands OPC 30050 gives methods for, as the profile names its events.
COMMANDS = ("Abort", "Clear", "Hold", "Reset", "Start", "Stop", "Suspend", "Unhold", "Unsuspend")
#: holder state (None: the device's top machine) -> (machine name, its object type's name)
MACHINES: dict[str | None, tuple[str, str]] = {
    None: ("BaseStateMachine", "PackMLBaseStateMachineType"),
    "Cleared": ("MachineState", "PackMLMachineStateMachineType"),
    "Running": ("ExecuteState", "PackMLExecuteStateMachineType"),
}


@dataclass(frozen=True, slots=True)
class PackmlNaming:
    """One device's PackML names: per machine index its name and type, and its methods."""

    machines: dict[int, tuple[str, str]]
    methods: dict[int, tuple[str, ...]]


def naming(chart: Chart, lay: Layout) -> PackmlNaming | None:
    """The PackML names of a device that declares the profile (rules 2 and 4), else None."""
    if chart.profile.lower() != PROFILE:
        return None
    machines = {
        at: MACHINES[spec.holder]
        for at, spec in enumerate(lay.machines)
        if spec.holder in MACHINES and (spec.holder is not None or spec.name == "StateMachine")
    }
    home = {state: at for at, spec in enumerate(lay.machines) for state in spec.states}
    methods: dict[int, list[str]] = {}
    for t in chart.transitions:
        at = home.get(t.source)
        for event in t.events:
            if event in COMMANDS and event in lay.commands and at in machines:
                found = methods.setdefault(at, [])
                if event not in found:
                    found.append(event)
    return PackmlNaming(machines, {at: tuple(sorted(m)) for at, m in methods.items()})


def status_of(outcome: str) -> int | None:
    """The OPC UA status code of a PackML method's outcome (rule 4); None for Good."""
    ua = _ua()
    if outcome == Outcome.HANDLED:
        return None
    if outcome in {u.value for u in Outcome}:  # why the event changed nothing
        return int(ua.StatusCodes.BadInvalidState)
    return int(ua.StatusCodes.BadResourceUnavailable)


class PackmlSpace:
    """The PackML namespace, object types and folder of one server (rules 1, 2 and 5)."""

    def __init__(self, index: int, home: int, types: dict[str, Any], folder: Any) -> None:
        self.index, self.home, self.types, self.folder = index, home, types, folder

    def new_id(self) -> Any:
        """A new node id in statectl's namespace (the PackML one's ids are the nodeset's)."""
        return _ua().NodeId(0, self.home)

    def name(self, text: str) -> Any:
        return _ua().QualifiedName(text, self.index)

    @classmethod
    async def create(cls, server: Any, base_type: Any, home: int) -> PackmlSpace:
        index = await server.register_namespace(PACKML_URI)
        space = cls(index, home, {}, None)
        for _, type_name in MACHINES.values():
            space.types[type_name] = await base_type.add_object_type(
                space.new_id(), space.name(type_name)
            )
        space.folder = await server.nodes.objects.add_folder(
            space.new_id(), space.name("PackMLObjects")
        )
        return space

    def machine(self, names: PackmlNaming | None, at: int) -> tuple[Any, Any, Any] | None:
        """Where, the browse name and the object type id of machine ``at``, if PackML names it."""
        if names is None or at not in names.machines:
            return None
        name, type_name = names.machines[at]
        return self.new_id(), self.name(name), self.types[type_name].nodeid

    async def finish(
        self,
        device: Any,
        machines: list[Any],
        names: PackmlNaming,
        call: Callable[[str, Any], Callable[..., Any]],
    ) -> None:
        """Add the command methods to the machines and file the device (rules 4 and 5);
        ``call(command, machine)`` makes the handler of ``command`` on that machine."""
        ua = _ua()
        for at, commands in names.methods.items():
            for command in commands:
                held = machines[at]
                await held.add_method(
                    self.new_id(), self.name(command), call(command, held.nodeid), [], []
                )
        await self.folder.add_reference(device.nodeid, ua.ObjectIds.Organizes)


def packml_call(outcome: Callable[[Any, Any], Any]) -> Callable[[Any, Any], Any]:
    """What a PackML method does once its call was checked (object, inputs, user: see
    :mod:`statectl.channels.opcua.methods`): await ``outcome(data, origin)``, answer Good
    or a bad status (rule 4)."""
    ua = _ua()

    async def call(data: Any, origin: Any) -> Any:
        code = status_of(await outcome(data, origin))
        return [] if code is None else ua.StatusCode(code)

    return call


def _ua() -> Any:
    """asyncua's ``ua`` module, untyped here: asyncua is optional and its stubs are partial."""
    from asyncua import ua

    return ua
