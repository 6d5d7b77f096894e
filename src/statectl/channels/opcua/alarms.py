"""OPC UA alarms for a device's faults (OPC 10000-9, Alarms and Conditions), on asyncua.

Rules:
1. Which. Every fault event a monitored state raises (the device's monitors,
   :func:`statectl.front.observers.extract`) is one condition of the device: an
   ``AlarmConditionType`` object ``Alarms/<fault>`` under the device object,
   referenced from it with ``HasCondition``. Its events come from the device object
   and from the ``Server`` object (where alarm clients subscribe), with the
   condition's node id as ``ConditionId``.
2. Raised. A step that takes a transition on the fault makes the alarm active:
   ``ActiveState`` True, ``AckedState`` False, ``Retain`` True, ``Severity`` the
   event's ``severity`` column (:data:`DEFAULT_SEVERITY` when it has none),
   ``Message`` the fault's detail (its data's ``detail``, else the fault's name).
3. Retain while the device is in the state that transition entered; the first step
   that leaves it (the device recovered) clears the alarm: ``ActiveState`` False and
   ``Retain`` False. Each change is one event.
4. ``Acknowledge(EventId, Comment)`` on the condition (the type's method or the
   instance's): the latest ``EventId`` only (else ``BadEventIdUnknown``), once
   (``BadConditionBranchAlreadyAcked``), by the configured user (anonymous is
   ``BadUserAccessDenied``). It sets ``AckedState`` True, ``Comment`` and
   ``ClientUserId``, fires an event and, in a journalled run, is journalled as an
   ``acknowledged: ORIGIN`` step on the device's owner. ``Enable``, ``Disable``
   and ``AddComment`` are ``BadNotSupported``: an alarm is always enabled.
5. ``ConditionRefresh(SubscriptionId)`` and ``ConditionRefresh2(SubscriptionId,
   MonitoredItemId)`` on ``ConditionType`` send that subscription (that item) a
   ``RefreshStartEvent``, the latest event of every retained condition, and a
   ``RefreshEndEvent``; an unknown subscription is ``BadSubscriptionIdInvalid``.
   Anonymous sessions may call them (access.py).
6. The condition object's variables hold its latest event's fields (``uaread`` of
   ``ActiveState/Id`` reads the state), and every one holds a value of its type
   before the first fault.
"""

from __future__ import annotations

import contextlib
import uuid
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from statectl.channels.opcua.access import caller
from statectl.channels.opcua.access import ua_module as _ua
from statectl.channels.opcua.nodes import browse
from statectl.front.observers import extract
from statectl.kernel.model import Chart
from statectl.run.commands import Origin
from statectl.run.runtime import Taken
from statectl.run.system import System

__all__ = ["DEFAULT_SEVERITY", "AlarmSpace", "alarm_events"]

#: An alarm's severity when its fault's row gives none (OPC UA: 1 lowest .. 1000 highest).
DEFAULT_SEVERITY = 500
_NEVER = datetime(1601, 1, 1, tzinfo=UTC)


def alarm_events(chart: Chart) -> tuple[str, ...]:
    """The faults that raise alarms (rule 1), in the chart's order of monitored states."""
    found: dict[str, None] = {}
    for spec in extract(chart).monitors:
        found.update(dict.fromkeys(spec.raises))
    return tuple(found)


@dataclass(slots=True)
class _Alarm:
    device: str
    fault: str
    severity: int
    node: Any
    event: Any  # the condition's asyncua event object (its latest fields)
    notifiers: tuple[Any, ...]  # the device object's node id and the Server's
    mirror: dict[str, tuple[Any, Any]] = field(default_factory=dict)  # field -> (node, type)
    targets: tuple[str, ...] = ()  # the states that retain it (rule 3)


class AlarmSpace:
    """The alarms of one server's devices (rules 1-6); its methods run on the server loop."""

    def __init__(self, server: Any, system: System) -> None:
        self.server, self.system = server, system
        self.by_device: dict[str, list[_Alarm]] = {}
        self.by_node: dict[Any, _Alarm] = {}
        self._refresh: dict[int, Any] = {}  # RefreshStart/End event type -> its event

    @classmethod
    async def create(cls, server: Any, system: System) -> AlarmSpace:
        """The server-wide methods (rules 4 and 5) and the refresh events."""
        from asyncua.server.event_generator import EventGenerator

        ua = _ua()
        space = cls(server, system)
        session = server.iserver.isession
        for kind in (ua.ObjectIds.RefreshStartEventType, ua.ObjectIds.RefreshEndEventType):
            gen = EventGenerator(session)
            await gen.init(kind, add_generates_event=False)
            space._refresh[kind] = gen.event
        bind = session.add_method_callback
        bind(ua.NodeId(ua.ObjectIds.ConditionType_ConditionRefresh), space.condition_refresh)
        bind(ua.NodeId(ua.ObjectIds.ConditionType_ConditionRefresh2), space.condition_refresh)
        bind(ua.NodeId(ua.ObjectIds.AcknowledgeableConditionType_Acknowledge), space.acknowledge)
        for method in ("Enable", "Disable", "AddComment"):
            bind(ua.NodeId(getattr(ua.ObjectIds, f"ConditionType_{method}")), _not_supported)
        return space

    async def add_device(self, idx: int, name: str, node: Any, chart: Chart) -> None:
        """Rule 1: the device's conditions, each in its initial state (rule 6)."""
        from asyncua.server.event_generator import EventGenerator

        ua = _ua()
        faults = alarm_events(chart)
        self.by_device[name] = []
        if not faults:
            return
        folder = await node.add_folder(idx, "Alarms")
        kind = ua.ObjectIds.AlarmConditionType
        server_id = ua.NodeId(ua.ObjectIds.Server)
        for at, fault in enumerate(faults):
            condition = await folder.add_object(
                idx, browse(fault), objecttype=kind, instantiate_optional=False
            )
            await node.add_reference(condition.nodeid, ua.ObjectIds.HasCondition)
            gen = EventGenerator(self.server.iserver.isession)
            await gen.init(kind, emitting_node=node.nodeid, add_generates_event=at == 0)
            declared = chart.event(fault)
            severity = declared.severity if declared and declared.severity else DEFAULT_SEVERITY
            for key, typed in list(gen.event.data_types.items()):  # asyncua cannot send a
                if (variant := _variant_type(typed)) is not None:  # time typed by its id
                    gen.event.data_types[key] = variant
            alarm = _Alarm(name, fault, severity, condition, gen.event, (node.nodeid, server_id))
            _initial(alarm)
            await self._bind_methods(condition)
            await self._mirror_nodes(alarm)
            await self._write_mirror(alarm)
            self.by_device[name].append(alarm)
            self.by_node[condition.nodeid] = alarm

    async def _bind_methods(self, condition: Any) -> None:
        ua = _ua()
        for child in await condition.get_children(refs=ua.ObjectIds.HasComponent):
            if await child.read_node_class() != ua.NodeClass.Method:
                continue
            name = (await child.read_browse_name()).Name
            call = self.acknowledge if name == "Acknowledge" else _not_supported
            self.server.link_method(child, call)

    async def _mirror_nodes(self, alarm: _Alarm) -> None:
        """Rule 6: the condition's variables, by the event field each one holds."""
        ua = _ua()
        for name, kind in alarm.event.data_types.items():
            variant = _variant_type(kind)
            if variant is None:
                continue
            path = [f"0:{part}" for part in name.split("/")]
            with contextlib.suppress(ua.UaError):
                alarm.mirror[name] = (await alarm.node.get_child(path), variant)

    async def _write_mirror(self, alarm: _Alarm) -> None:
        ua = _ua()
        for name, (node, variant) in alarm.mirror.items():
            value = getattr(alarm.event, name, None)
            if value is None:
                continue
            await self.server.write_attribute_value(
                node.nodeid, ua.DataValue(ua.Variant(value, variant))
            )

    # -- after each step (rules 2 and 3) -----------------------------------------------------

    async def stepped(
        self,
        device: str,
        active: frozenset[str],
        records: Sequence[object],
        fault: tuple[str, Any] | None,
    ) -> None:
        """Raise the alarm of ``fault`` (its event and data) whose transition the step took
        (in ``records``), and clear those whose retaining states the device left."""
        alarms = self.by_device.get(device)
        if not alarms:  # most devices: nothing to do after a step
            return
        faults = {a.fault for a in alarms}
        entered = {
            r.label: r.targets for r in records if isinstance(r, Taken) and r.label in faults
        }
        for alarm in alarms:
            if fault is not None and fault[0] == alarm.fault and alarm.fault in entered:
                alarm.targets = tuple(entered[alarm.fault])
                await self._raise(alarm, fault[1])
            elif alarm.targets and not active.intersection(alarm.targets):
                alarm.targets = ()
                await self._clear(alarm)

    async def _raise(self, alarm: _Alarm, data: Any) -> None:
        ua = _ua()
        detail = data.get("detail") if isinstance(data, dict) else None
        text = str(detail) if detail is not None else alarm.fault
        now = datetime.now(UTC)
        ev = alarm.event
        ev.Message = ua.LocalizedText(text)
        ev.Severity = ev.LastSeverity = alarm.severity
        setattr(ev, "LastSeverity/SourceTimestamp", now)
        _two_state(ev, "ActiveState", True, "Active", "Inactive", now)
        _two_state(ev, "AckedState", False, "Acknowledged", "Unacknowledged", now)
        ev.Comment = ua.LocalizedText("")
        ev.ClientUserId = ""
        ev.Retain = True
        await self._fire(alarm, now)

    async def _clear(self, alarm: _Alarm) -> None:
        now = datetime.now(UTC)
        _two_state(alarm.event, "ActiveState", False, "Active", "Inactive", now)
        alarm.event.Retain = False
        await self._fire(alarm, now)

    async def _fire(self, alarm: _Alarm, now: datetime) -> None:
        ev = alarm.event
        ev.EventId = uuid.uuid4().bytes
        ev.Time = ev.ReceiveTime = now
        await self._write_mirror(alarm)
        service = self.server.iserver.subscription_service
        for notifier in alarm.notifiers:  # rule 1: from the device and the Server
            ev.emitting_node = notifier
            await service.trigger_event(ev)

    # -- methods (rules 4 and 5) -------------------------------------------------------------

    async def acknowledge(self, parent: Any, *args: Any) -> Any:
        """Rule 4: ``Acknowledge(EventId, Comment)`` on a condition."""
        ua = _ua()
        alarm = self.by_node.get(parent)
        if alarm is None:
            return _status("BadMethodInvalid")
        if len(args) != 2:
            return _status("BadArgumentsMissing" if len(args) < 2 else "BadTooManyArguments")
        event_id, comment = args
        if getattr(event_id, "VariantType", None) != ua.VariantType.ByteString or getattr(
            comment, "VariantType", None
        ) not in (ua.VariantType.LocalizedText, ua.VariantType.String):
            return _status("BadInvalidArgument")
        user = caller()
        if user is None:
            return _status("BadUserAccessDenied")
        if event_id.Value != alarm.event.EventId:
            return _status("BadEventIdUnknown")
        if getattr(alarm.event, "AckedState/Id"):
            return _status("BadConditionBranchAlreadyAcked")
        text = comment.Value if isinstance(comment.Value, str) else (comment.Value.Text or "")
        now = datetime.now(UTC)
        ev = alarm.event
        _two_state(ev, "AckedState", True, "Acknowledged", "Unacknowledged", now)
        ev.Comment = ua.LocalizedText(text)
        setattr(ev, "Comment/SourceTimestamp", now)
        ev.ClientUserId = user
        await self._fire(alarm, now)
        self._journal(alarm, text, Origin("opcua", user))
        return []

    def _journal(self, alarm: _Alarm, comment: str, origin: Origin) -> None:
        """Rule 4: journal the acknowledgement on the device's owner, after its steps."""
        bound = self.system.bound.get(alarm.device)
        if bound is None:
            return
        # on the owner, in order with the device's steps; whether here: the door's to say
        self.system.call_soon(
            alarm.device, lambda: bound.acknowledged(alarm.fault, comment, str(origin))
        )

    async def condition_refresh(self, parent: Any, *args: Any) -> Any:
        """Rule 5: the retained conditions again, between RefreshStart and RefreshEnd."""
        ua = _ua()
        if not args or len(args) > 2:
            return _status("BadArgumentsMissing" if not args else "BadTooManyArguments")
        values = [getattr(a, "Value", None) for a in args]
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in values):
            return _status("BadInvalidArgument")
        subscription = self.server.iserver.subscription_service.subscriptions.get(values[0])
        if subscription is None:
            return _status("BadSubscriptionIdInvalid")
        items = subscription.monitored_item_srv
        item = values[1] if len(values) == 2 else None
        if item is not None and item not in getattr(items, "_monitored_items", {}):
            return _status("BadMonitoredItemIdInvalid")
        retained = [a for alarms in self.by_device.values() for a in alarms if a.event.Retain]
        notifiers = {ua.NodeId(ua.ObjectIds.Server)} | {
            n for alarms in self.by_device.values() for a in alarms for n in a.notifiers
        }
        start, end = (self._refresh[k] for k in _REFRESH)
        await _deliver(items, start, notifiers, item)
        for alarm in retained:
            await _deliver(items, alarm.event, alarm.notifiers, item)
        await _deliver(items, end, notifiers, item)
        return []


_REFRESH = (2787, 2788)  # RefreshStartEventType, RefreshEndEventType


async def _deliver(items: Any, event: Any, notifiers: Any, item: int | None) -> None:
    """Send ``event`` to one subscription's items on each notifier (or to one item)."""
    if event.EventType.Identifier in _REFRESH:
        event.EventId = uuid.uuid4().bytes
        event.Time = event.ReceiveTime = datetime.now(UTC)
    for notifier in notifiers:
        event.emitting_node = notifier
        await items.trigger_event(event, item)


def _initial(alarm: _Alarm) -> None:
    """Rule 6: the fields of a condition that never fired (inactive, acknowledged)."""
    ua = _ua()
    ev = alarm.event
    ev.NodeId = alarm.node.nodeid
    ev.EventId = b""
    ev.Time = ev.ReceiveTime = _NEVER
    ev.Message = ua.LocalizedText("")
    ev.Severity = ev.LastSeverity = alarm.severity
    ev.ConditionClassId = ua.NodeId(ua.ObjectIds.ProcessConditionClassType)
    ev.ConditionClassName = ua.LocalizedText("ProcessConditionClassType")
    ev.ConditionName = alarm.fault
    ev.BranchId = ua.NodeId()
    ev.Retain = False
    ev.Quality = ua.StatusCode(ua.StatusCodes.Good)
    ev.Comment = ua.LocalizedText("")
    ev.ClientUserId = ""
    ev.InputNode = ua.NodeId()
    ev.SuppressedOrShelved = False
    for name in ("Quality", "LastSeverity", "Comment"):
        setattr(ev, f"{name}/SourceTimestamp", _NEVER)
    _two_state(ev, "EnabledState", True, "Enabled", "Disabled", _NEVER)
    _two_state(ev, "ActiveState", False, "Active", "Inactive", _NEVER)
    _two_state(ev, "AckedState", True, "Acknowledged", "Unacknowledged", _NEVER)


def _two_state(ev: Any, name: str, value: bool, true: str, false: str, now: datetime) -> None:
    """A TwoStateVariable of the event: its text, ``Id`` and the time it changed."""
    ua = _ua()
    setattr(ev, name, ua.LocalizedText(true if value else false))
    setattr(ev, f"{name}/Id", value)
    setattr(ev, f"{name}/TransitionTime", now)
    setattr(ev, f"{name}/TrueState", ua.LocalizedText(true))
    setattr(ev, f"{name}/FalseState", ua.LocalizedText(false))


def _variant_type(kind: Any) -> Any:
    """The variant type an event field is written as (a data type id for times)."""
    ua = _ua()
    if isinstance(kind, ua.VariantType):
        return kind
    if kind == ua.NodeId(ua.ObjectIds.UtcTime):
        return ua.VariantType.DateTime
    return None


def _status(name: str) -> Any:
    ua = _ua()
    return ua.StatusCode(getattr(ua.StatusCodes, name))


async def _not_supported(_parent: Any, *_args: Any) -> Any:
    """Rule 4: Enable, Disable and AddComment."""
    return _status("BadNotSupported")
