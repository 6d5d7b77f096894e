"""Readable lines of trace records: one per record, one per state and transition of a microstep.

Rules:
1. A line is ``t=<time>  <device>  <kind>  <text>``; time, device and kind are
   padded so the text column lines up down a trace. A ``MicrostepTaken`` is a line
   per state exited (``exit``), transition taken (``state``) and state entered
   (``enter``), in that order.
2. Event data reads like YAML flow style (``{amount: 10}``); API calls read like
   the call (``SimMotor.move_to(10.0)``).
3. No colour codes unless asked for (``colour=True``), so a trace can be
   diffed, logged and pasted.
4. Names are the user's and may hold a newline, an ANSI escape or a bidi control:
   every text column and device name goes through :func:`statectl.kernel.text.shown`,
   so one record is one line each and shows what the name holds.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, TextIO

from statectl.kernel.model import Notify
from statectl.kernel.semantics import Unhandled
from statectl.kernel.text import shown

if TYPE_CHECKING:
    from statectl.kernel.semantics import Step

from statectl.run.runtime.records import (
    ApiCall,
    EventIgnored,
    EventReceived,
    EventRejected,
    FaultDetected,
    Finished,
    InvokeIssued,
    MicrostepTaken,
    MonitorStarted,
    MonitorStopped,
    ObserverCalled,
    Record,
    Started,
    StepRecord,
    Taken,
    fields_of,
    records_plan,
)

__all__ = ["KINDS", "TraceWriter", "format_data", "format_record", "kind_of"]

KIND_WIDTH = 8
_COLOURS: Mapping[str, str] = {
    "event": "\x1b[1m",
    "state": "\x1b[36m",
    "invoke": "\x1b[35m",
    "api": "\x1b[35m",
    "ignored": "\x1b[33m",
    "rejected": "\x1b[31m",
    "fault": "\x1b[31m",
    "monitor": "\x1b[34m",
}
_RESET = "\x1b[0m"


def format_data(value: Any) -> str:
    """Event data in YAML flow style: ``{amount: 10, target: 2.5}``, every number exact
    (a trace or ``journal show`` that rounded would misreport what the device was sent)."""
    kind = type(value)
    if kind is int or kind is bool or value is None:  # the usual leaves, without the ABC checks
        return repr(value)
    if kind is dict or isinstance(value, Mapping):
        return "{" + ", ".join([f"{k}: {format_data(v)}" for k, v in value.items()]) + "}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(format_data(v) for v in value) + "]"
    if isinstance(value, str):
        plain = value and value.strip() == value and not any(c in value for c in ",:{}[]'\"#")
        return value if plain else repr(value)
    return repr(value)  # a float as its shortest exact text: 123456789.0 stays whole


def _states(names: tuple[str, ...]) -> str:
    return ", ".join(names) if names else "(targetless)"


#: The kind column of each record type (rule 1).
KINDS: Mapping[type, str] = {
    Started: "run",
    Finished: "run",
    EventReceived: "event",
    MicrostepTaken: "state",
    InvokeIssued: "invoke",
    ObserverCalled: "api",
    EventIgnored: "ignored",
    EventRejected: "rejected",
    MonitorStarted: "monitor",
    MonitorStopped: "monitor",
    FaultDetected: "fault",
}


def kind_of(record: Record) -> str:
    """The short kind column of a record (of its first line: a microstep's first exit,
    else its first transition, else its first entry)."""
    if type(record) is MicrostepTaken and not record.transitions:
        return "exit" if record.exited else "enter"
    if type(record) is MicrostepTaken and record.exited:
        return "exit"
    return KINDS[type(record)]


def _event_text(r: Any) -> str:
    return shown(r.event if r.data is None else f"{r.event} {format_data(r.data)}")


def _transition_text(t: Taken) -> str:
    return f"{_states((t.source,))} -> {_states(t.targets)}  on {t.label or '(eventless)'}"


def _rejected_text(r: Any) -> str:
    if r.reason is Unhandled.GUARD_ERROR:  # refused whatever the policy (runtime/eventdata.py)
        return f"{r.event} ({r.reason})"
    return f"{r.event} ({r.reason}; policy error)"


#: The text column of each record type, one function per type (no match per record).
_TEXTS: Mapping[type, Callable[[Any], str]] = {
    Started: lambda r: "started",
    Finished: lambda r: "finished",
    EventReceived: _event_text,
    InvokeIssued: lambda r: f"#{r.invoke} {r.name} -> observer {r.method}()",
    ObserverCalled: lambda r: f"{r.method}() -> {r.api}",
    EventIgnored: lambda r: f"{r.event} ({r.reason})",
    EventRejected: _rejected_text,
    MonitorStarted: lambda r: f"{r.state} started",
    MonitorStopped: lambda r: f"{r.state} stopped",
    FaultDetected: lambda r: f"{r.detail!r} while {r.state} -> raises {r.event}",
}


def _lines(record: Record, kinds: Mapping[str, str]) -> list[str]:
    """The lines of ``record`` after the time and device column, each with its kind
    column (``kinds`` maps a kind to it) and ending in a newline."""
    if type(record) is not MicrostepTaken:
        return [kinds[KINDS[type(record)]] + shown(_TEXTS[type(record)](record)) + "\n"]
    return [
        *[kinds["exit"] + shown(s) + "\n" for s in record.exited],
        *[kinds["state"] + shown(_transition_text(t)) + "\n" for t in record.transitions],
        *[kinds["enter"] + shown(s) + "\n" for s in record.entered],
    ]


def _padded(kind: str, colour: bool) -> str:
    padded = f"{kind:<{KIND_WIDTH}}"
    return f"{_COLOURS.get(kind, '')}{padded}{_RESET}" if colour else padded


def _kind_columns(colour: bool) -> dict[str, str]:
    """The kind column of every line kind, padded (and coloured if asked)."""
    return {k: " " + _padded(k, colour) + " " for k in (*KINDS.values(), "exit", "enter")}


#: The kind columns without colour.
_PLAIN = _kind_columns(False)


def format_record(record: Record, *, device_width: int = 0, colour: bool = False) -> str:
    """The record's aligned lines (one, or one per state and transition of a
    ``MicrostepTaken``), without a final newline:
    ``t=   0.00  Motor  event    Movement {amount: 10}``."""
    kinds = _kind_columns(True) if colour else _PLAIN
    prefix = f"t={record.time:7.2f}  {shown(record.device):<{device_width}} "
    return "".join([prefix + line for line in _lines(record, kinds)])[:-1]


#: Distinct record lines a writer keeps the text of (then it starts again).
_REST_MAX = 4096


class TraceWriter:
    """Writes each record as a line to ``out``: a record listener, or a step listener.

    As a step listener (``subject.listen_steps(writer.step)``) it writes one step's
    lines with one ``write`` (no flush: ``out``'s own buffering applies). The time
    and device column is made once per time and device, the rest of a line once per
    distinct record (a device's records repeat: the same states, transitions and
    notifications), so a line costs a lookup and a concatenation.
    """

    def __init__(self, out: TextIO, *, device_width: int = 0, colour: bool = False) -> None:
        self.out = out
        self.device_width = device_width
        self.colour = colour
        self.lines = 0
        self._kinds = _kind_columns(colour)
        self._at: tuple[float, str] | None = None  # (time, device) of ``_prefix``
        self._prefix = ""
        self._rest: dict[tuple[type, tuple[Any, ...]], list[str]] = {}  # lines after the prefix
        self._steps: dict[int, tuple[Step, list[list[str] | tuple[str]]]] = {}  # per kernel step
        self._received: dict[str | None, str] = {}  # EventReceived without data, per event
        self._calls: dict[tuple[str, str], str] = {}  # ObserverCalled, per method and api
        self._apis: dict[tuple[Any, ...], str] = {}  # ObserverCalled, per logged call

    def _line(self, record: Record) -> tuple[str, int]:
        """The record's lines, and how many."""
        prefix = self._column(record.time, record.device)
        if type(record) is EventReceived and record.data is not None:  # may be unhashable
            return prefix + self._kinds["event"] + _event_text(record) + "\n", 1
        rests = self._rest.get((type(record), fields_of(record)))
        if rests is None:  # not kept yet (:meth:`_rests` keeps it)
            rests = self._rests(record)
        return prefix + prefix.join(rests), len(rests)

    def _rests(self, record: Record) -> list[str]:
        """The record's lines after the time and device column."""
        if type(record) is EventReceived and record.data is not None:  # may be unhashable
            return [self._kinds["event"] + _event_text(record) + "\n"]
        key = (type(record), fields_of(record))
        rests = self._rest.get(key)
        if rests is None:  # kind and text once per distinct record (time and device aside)
            if len(self._rest) >= _REST_MAX:
                self._rest.clear()
            rests = self._rest[key] = _lines(record, self._kinds)
        return rests

    def _column(self, time: float, device: str) -> str:
        """The time and device column, made once per time and device."""
        at = (time, device)
        if at != self._at:
            self._at = at
            self._prefix = f"t={time:7.2f}  {shown(device):<{self.device_width}} "
        return self._prefix

    def __call__(self, record: Record) -> None:
        text, n = self._line(record)
        self.out.write(text)
        self.lines += n

    def step(self, step: StepRecord) -> None:
        """A step listener: every line of ``step``'s records, in one write.

        A plan's usual step is written from its kernel step without building its typed
        records: the text after the time and device column is kept per step (the same
        states, transitions and notifications repeat), so the step's lines are one
        ``join`` with that column.
        """
        kernel, tail = step.step, step._tail
        if kernel is None or (tail is not None and (tail.final or tail.upto is not None)):
            lines = [self._line(r) for r in step.records]  # unhandled, finished or failed
            self.out.write("".join([text for text, _ in lines]))
            self.lines += sum(n for _, n in lines)
            return
        hit = self._steps.get(id(kernel))
        if hit is None or hit[0] is not kernel:
            if len(self._steps) >= _REST_MAX:
                self._steps.clear()
            hit = self._steps[id(kernel)] = (kernel, self._step_lines(kernel))
        prefix = self._column(step.time, step.device)
        event = step.event
        rest = self._received.get(event) if step.data is None else None
        if rest is None:
            rest = self._kinds["event"] + _event_text(step) + "\n"
            if step.data is None:
                self._received[event] = rest
        extras = tail.extras if tail is not None else ()
        starts = [0] if extras else None  # the line each typed record starts at
        rests = [rest]
        made = step._made
        k = 0
        for item in hit[1]:
            if type(item) is not tuple:  # a record's lines
                if starts is not None:
                    starts.append(len(rests))
                rests.extend(item)
                continue
            did = made[k] if k < len(made) else None
            k += 1
            if isinstance(did, str):
                if starts is not None:
                    starts.append(len(rests))
                rests.append(self._called(item[0], did))
            elif did is not None:
                for c in did:
                    if starts is not None:
                        starts.append(len(rests))
                    rests.append(self._logged(item[0], c))
        if starts is not None:  # what others recorded meanwhile, in place
            starts.append(len(rests))
            if any(r.time != step.time or r.device != step.device for _, r in extras):
                self._write_apart(prefix, rests, starts, extras)
                return
            added = 0
            for before, record in extras:  # at the step's time: lines of the same column
                at = starts[min(before, len(starts) - 1)] + added
                more = self._rests(record)
                rests[at:at] = more
                added += len(more)
        self.out.write(prefix + prefix.join(rests))
        self.lines += len(rests)

    def _write_apart(
        self,
        prefix: str,
        rests: list[str],
        starts: list[int],
        extras: tuple[tuple[int, Record], ...] | list[tuple[int, Record]],
    ) -> None:
        """A step's lines with records made meanwhile at another time, each its own column."""
        out = [prefix + r for r in rests]  # and what others recorded meanwhile, in place
        for shift, (before, record) in enumerate(extras):
            at = starts[min(before, len(starts) - 1)] + shift
            text, n = self._line(record)  # its own time
            out.insert(at, text)
            self.lines += n - 1
        self.out.write("".join(out))
        self.lines += len(out)

    def _step_lines(self, kernel: Step) -> list[list[str] | tuple[str]]:
        """The lines of each of ``kernel``'s records after ``EventReceived``, with
        each notification's observer calls as ``(method,)`` (they vary per event)."""
        lines: list[list[str] | tuple[str]] = []
        for item in records_plan(kernel):
            if isinstance(item, Notify):
                lines.append((item.method,))
                continue
            kind, fields = item
            record = kind("", 0.0, *fields)  # only to render its text, once per step
            lines.append(_lines(record, self._kinds))
        return lines

    def _logged(self, method: str, call: ApiCall) -> str:
        """The text of an ``ObserverCalled`` line for a logged API call, kept per call
        (the same calls with the same arguments repeat; ``str()`` of a call is not cheap)."""
        try:
            key = (method, call.device, call.function, call.args)
            rest = self._apis.get(key)
        except TypeError:  # an argument that cannot be a key (a list)
            return self._called(method, str(call))
        if rest is None:
            if len(self._apis) >= _REST_MAX:
                self._apis.clear()
            rest = self._apis[key] = self._called(method, str(call))
        return rest

    def _called(self, method: str, api: str) -> str:
        """The text of an ``ObserverCalled`` line, kept per method and call."""
        key = (method, api)
        rest = self._calls.get(key)
        if rest is None:
            if len(self._calls) >= _REST_MAX:
                self._calls.clear()
            rest = self._calls[key] = f"{self._kinds['api']}{shown(f'{method}() -> {api}')}\n"
        return rest
