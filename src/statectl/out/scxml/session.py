"""The SCXML interpreter: sessions, queues, ``<send>`` on a clock, ``<invoke>``.

The W3C algorithm itself lives in :mod:`statectl.kernel.semantics`; a session drives it
microstep by microstep and performs the executable content it hands over. Rules:

1. A :class:`Session` owns one datamodel, one :class:`~statectl.kernel.semantics.Run`
   (configuration and internal queue) and one external queue. It follows the
   spec's ``mainEventLoop``: settle (eventless, then internal events), start the
   invokes of states entered and still active, and only then take one external
   event, applying ``<finalize>`` and autoforward first.
2. Errors in executable content end the block and put ``error.execution`` on the
   internal queue at once; an undeliverable send puts ``error.communication``.
3. A :class:`Scheduler` runs every session of a document (parent and invoked
   children) in one thread, round-robin until all are idle, then advances the
   runtime's :class:`~statectl.run.runtime.clock.Clock` to the next delayed send. A
   :class:`~statectl.run.runtime.clock.SimClock` (alias ``SimulatedClock``) makes a
   timed run deterministic and instant; a :class:`~statectl.run.runtime.clock.WallClock`
   (alias ``RealClock``) really waits.
4. Send targets: none (own external queue), ``#_internal``, ``#_parent``,
   ``#_<invokeid>``, ``#_scxml_<sessionid>``; other targets are
   ``error.execution``, unreachable sessions ``error.communication``.
5. Bounds (docs/security.md): a run given a wall-clock deadline
   (:attr:`Scheduler.wall_deadline`) checks it at every condition, block, action,
   foreach iteration, state entry and event, and raises :class:`SessionTimeout`
   once it has passed, whatever the document does. Invokes nest at most
   :data:`MAX_INVOKE_DEPTH` deep with at most :data:`MAX_SESSIONS` running
   sessions; a ``src`` file (``<data>``, ``<invoke>``) must be a regular file of
   at most :data:`MAX_SRC_BYTES` bytes. Beyond a bound: ``error.execution``.
6. Trust: a ``python`` document is trusted and reads ``src`` files anywhere. A
   ``safe`` or ``null`` document reads files only inside the top document's
   directory (no ``..``, no absolute path, no symlink out): ``<invoke src>``
   always, ``<data src>`` only if the session is created with ``allow_src=True``
   (``statectl scxml run --allow-src``), since its content becomes readable data.
"""

from __future__ import annotations

import itertools
import uuid
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from statectl.kernel.model import (
    Action,
    Assign,
    Block,
    Cancel,
    Chart,
    ChildInvoke,
    Content,
    Foreach,
    If,
    Log,
    Param,
    Raise,
    Script,
    Send,
    State,
    Transition,
)
from statectl.kernel.semantics import (
    Event,
    Machine,
    Microstep,
    Run,
    enter_initial_states,
    exit_interpreter,
    macrostep,
    process_event,
)
from statectl.out.scxml import sending
from statectl.out.scxml.datamodel import (
    Datamodel,
    EvaluationError,
    inline_value,
    make_datamodel,
)
from statectl.out.scxml.safecheck import src_outside
from statectl.out.scxml.scheduler import Scheduler
from statectl.out.scxml.sending import (
    SCXML_IO,
    SendError,
)
from statectl.out.scxml.timeouts import cancel_of, send_of
from statectl.out.scxml.xmltree import read_src_text

__all__ = ["Session"]


class EventData(dict[str, Any]):
    """``_event.data`` from ``<param>``/``namelist``: a dict that also reads as attributes."""

    def __getattr__(self, name: str) -> Any:
        try:
            return self[name]
        except KeyError as exc:
            raise AttributeError(name) from exc


@dataclass(frozen=True, slots=True)
class IOProcessor:
    location: str


class Session:
    """One running SCXML document; the :class:`~statectl.kernel.semantics.Executor` of its run."""

    def __init__(
        self,
        chart: Chart,
        scheduler: Scheduler,
        *,
        base: Path | None = None,
        parent: Session | None = None,
        invokeid: str = "",
        initial_data: Mapping[str, Any] | None = None,
        allow_src: bool = False,
    ) -> None:
        self.chart = chart
        self.machine = Machine(chart)
        self.scheduler = scheduler
        self.base = base or Path.cwd()
        self.parent = parent
        self.invokeid = invokeid
        self.sessionid = uuid.uuid4().hex
        self.run = Run(set(), {}, None, {}, executor=self)
        self.datamodel: Datamodel = make_datamodel(chart.datamodel, self.run.active.__contains__)
        # A python document is trusted by whoever runs it; its children inherit that,
        # nobody else's does (a safe parent's python child is refused in ``invoke``).
        self.trusted: bool = chart.datamodel == "python" and (parent is None or parent.trusted)
        # An untrusted session reads src files only if the top session allows it, and
        # then only under the top document's directory.
        self.allow_src: bool = parent.allow_src if parent is not None else allow_src
        self.src_root: Path = parent.src_root if parent is not None else self.base.resolve()
        self.depth: int = parent.depth + 1 if parent is not None else 0
        self.external: deque[Event] = deque()
        self.running = True
        self.started = False
        self.final_state: str | None = None
        #: The latest microsteps (for inspection); the livelock bound counts one macrostep.
        self.microsteps: deque[Microstep] = deque(maxlen=1000)
        self.to_invoke: list[str] = []
        self.invocations: dict[str, tuple[str, ChildInvoke, Session | None]] = {}  # id -> state
        self.bound: set[str] = set()
        self.initial_data = dict(initial_data or {})
        self._ids = itertools.count(1)
        scheduler.sessions[self.sessionid] = self

    # -- the queues -----------------------------------------------------------------------------

    @property
    def ready(self) -> bool:
        return self.running and (not self.started or bool(self.external))

    @property
    def origin(self) -> str:
        return "#_scxml_" + self.sessionid

    def post(self, event: Event) -> None:
        """Append an external event (from a send, a child, a parent or the host)."""
        if self.running:
            self.external.append(event)

    def error(self, name: str, sendid: str = "", data: Any = None) -> None:
        self.run.raise_event(Event(name, data, "platform", sendid))

    # -- the main loop --------------------------------------------------------------------------

    def start(self) -> None:
        """``interpret``: bind data, run the top-level script, enter the initial states."""
        self.started = True
        dm = self.datamodel
        dm.set_system("_sessionid", self.sessionid)
        dm.set_system("_name", self.chart.name)
        location = IOProcessor(self.origin)
        dm.set_system("_ioprocessors", {SCXML_IO: location, "scxml": location})
        dm.set_system("_event", None)
        late = self.chart.binding == "late"
        for item in self.chart.data:
            self.bind(item.name, item.expr, item.src, item.body)
        for s in self.chart.states:
            for item in s.data:
                if late:
                    dm.declare(item.name, None)
                else:
                    self.bind(item.name, item.expr, item.src, item.body)
        if not late:
            self.bound.update(s.name for s in self.chart.states)
        for script in self.chart.script:
            self.execute(self.run, (script,))
        self.microsteps.append(enter_initial_states(self.machine, self.run))
        self.settle()

    def bind(self, name: str, expr: str | None, src: str | None, body: str | None) -> None:
        dm = self.datamodel
        if name in self.initial_data:
            dm.declare(name, self.initial_data[name])
            return
        try:
            dm.declare(name, None)
            if expr is not None:
                dm.declare(name, dm.evaluate(expr))
            elif src is not None:
                dm.declare(name, inline_value(self.read_src(src, data=True)[0]))
            elif body is not None:
                dm.declare(name, inline_value(body))
        except EvaluationError as exc:
            self.scheduler.trace(f"error.execution: <data id={name!r}>: {exc}")
            self.error("error.execution")

    def read_src(self, src: str, *, data: bool = False) -> tuple[str, Path]:
        """The text of a ``src`` file and its directory, within this session's trust."""
        path = self.base / src.strip().removeprefix("file:")
        if not self.trusted:
            kind = self.chart.datamodel
            if data and not self.allow_src:
                raise EvaluationError(
                    f"src {src!r} refused: a {kind!r} document reads no files unless run "
                    "with --allow-src (then only inside its own directory)"
                )
            why = src_outside(src, path, self.src_root)
            if why is not None:
                raise EvaluationError(f"src {src!r} refused: it {why}")
        try:
            return read_src_text(path), path.parent
        except OSError as exc:
            raise EvaluationError(f"cannot read src {src!r}: {exc.strerror}") from exc
        except ValueError as exc:
            raise EvaluationError(f"src {src!r} {exc}") from exc

    def settle(self) -> None:
        """The inner loop of ``mainEventLoop``, then the invokes it made due."""
        while self.running:
            self.scheduler.check_deadline()
            steps: list[Microstep] = []
            try:
                macrostep(self.machine, self.run, steps)
            finally:
                self.microsteps.extend(steps)
            if self.run.final:
                self.finish()
                return
            states = sorted(set(self.to_invoke), key=self.machine.order.__getitem__)
            self.to_invoke.clear()
            for name in states:
                for definition in self.chart.states[self.machine.order[name]].invokes:
                    self.invoke(name, definition)
            if not self.run.internal:
                return

    def run_available(self) -> None:
        """Process every queued external event, each to completion."""
        if not self.started:
            self.start()
        while self.running and self.external:
            self.scheduler.check_deadline()
            event = self.external.popleft()
            self.datamodel.set_system("_event", event)
            self.run.current = event
            entry = self.invocations.get(event.invokeid) if event.invokeid else None
            if entry is not None and entry[1].finalize:
                self.execute(self.run, entry[1].finalize)
            for _state, definition, child in list(self.invocations.values()):
                if definition.autoforward and child is not None and child.running:
                    child.post(replace(event))
            step = process_event(self.machine, self.run, event)
            if step is not None:
                self.microsteps.append(step)
            self.settle()

    def finish(self) -> None:
        """``exitInterpreter``: exit every state; tell the parent with ``done.invoke``."""
        final = self.run.final_state
        data = None
        if final is not None:
            data = self.done_data(self.run, self.chart.states[self.machine.order[final]])
        exit_interpreter(self.machine, self.run)
        self.running = False
        self.final_state = final
        if self.parent is not None and final is not None:
            self.parent.post(
                Event(
                    f"done.invoke.{self.invokeid}",
                    data,
                    "external",
                    "",
                    self.origin,
                    SCXML_IO,
                    self.invokeid,
                )
            )

    def cancel(self) -> None:
        """Stop an invoked session its parent no longer wants (no ``done.invoke``)."""
        if self.running:
            self.running = False
            for _s, _d, child in self.invocations.values():
                if child is not None:
                    child.cancel()
        self.scheduler.sessions.pop(self.sessionid, None)

    # -- the Executor protocol ------------------------------------------------------------------

    def _bind_event(self, run: Run) -> None:
        self.datamodel.set_system("_event", run.current)

    def condition(self, run: Run, transition: Transition) -> bool:
        assert transition.guard is not None
        self.scheduler.check_deadline()
        self._bind_event(run)
        try:
            return self.datamodel.condition(transition.guard)
        except EvaluationError:
            self.error("error.execution")
            return False

    def state_entered(self, run: Run, state: State) -> None:
        self.scheduler.check_deadline()
        self.to_invoke.append(state.name)
        armed = send_of(state)  # a table timeout read back from SCXML (scxml/timeouts.py)
        if armed is not None:
            self.perform(armed)
        if state.name not in self.bound:
            self.bound.add(state.name)
            for item in state.data:
                self.bind(item.name, item.expr, item.src, item.body)

    def state_exited(self, run: Run, state: State) -> None:
        disarmed = cancel_of(state)
        if disarmed is not None:
            self.perform(disarmed)
        if state.name in self.to_invoke:
            self.to_invoke = [s for s in self.to_invoke if s != state.name]
        for invokeid, (owner, _definition, child) in list(self.invocations.items()):
            if owner == state.name:
                del self.invocations[invokeid]
                if child is not None:
                    child.cancel()

    def done_data(self, run: Run, state: State) -> Any:
        dd = state.donedata
        if dd is None:
            return None
        self._bind_event(run)
        try:
            if dd.content is not None:
                return self.content_value(dd.content)
            return self.params_value((), dd.params)
        except EvaluationError:
            self.error("error.execution")
            return None

    def execute(self, run: Run, actions: tuple[Action, ...]) -> None:
        """Perform one block; the first error ends it with ``error.execution``."""
        self.scheduler.check_deadline()
        self._bind_event(run)
        try:
            for action in actions:
                self.perform(action)
        except SendError as exc:
            self.scheduler.trace(f"{exc.event}: {exc}")
            self.error(exc.event, exc.sendid)
        except EvaluationError as exc:
            self.scheduler.trace(f"error.execution: {exc}")
            self.error("error.execution")

    # -- executable content ---------------------------------------------------------------------

    def perform(self, action: Action) -> None:
        self.scheduler.check_deadline()
        dm = self.datamodel
        if isinstance(action, Block):
            self.execute(self.run, action.actions)
        elif isinstance(action, Raise):
            self.run.raise_event(Event(action.event))
        elif isinstance(action, Log):
            value = dm.evaluate(action.expr) if action.expr is not None else action.message
            try:
                text = str(value)
            except (RecursionError, ValueError) as exc:
                raise EvaluationError(f"<log> value cannot be shown: {exc!r}") from exc
            self.scheduler.log(
                f"{action.label}: {text}" if action.label and text else action.label or text
            )
        elif isinstance(action, Assign):
            if action.expr is not None:
                value = dm.evaluate(action.expr)
            else:
                value = inline_value(action.body or "")
            dm.assign(action.location, value)
        elif isinstance(action, Script):
            dm.run_script(action.source)
        elif isinstance(action, If):
            for cond, branch in action.branches:
                if cond is None or dm.condition(cond):
                    for a in branch:
                        self.perform(a)
                    break
        elif isinstance(action, Foreach):
            self.foreach(action)
        elif isinstance(action, Send):
            self.send(action)
        elif isinstance(action, Cancel):
            sendid = (
                action.sendid
                if action.sendid is not None
                else str(dm.evaluate(action.sendidexpr or "''"))
            )
            self.scheduler.cancel_timers(self, sendid)

    def foreach(self, action: Foreach) -> None:
        dm = self.datamodel
        array = dm.evaluate(action.array)
        try:
            items = list(array)
        except TypeError as exc:
            raise EvaluationError(f"foreach array {action.array!r} is not iterable") from exc
        for name in (action.item, action.index):
            if name is not None and not name.strip().isidentifier():
                raise EvaluationError(f"foreach item/index {name!r} is not a variable name")
        for i, item in enumerate(items):
            self.declare_or_assign(action.item, item)
            if action.index is not None:
                self.declare_or_assign(action.index, i)
            for a in action.actions:
                self.perform(a)

    def declare_or_assign(self, name: str, value: Any) -> None:
        if self.datamodel.declared(name.strip()):
            self.datamodel.assign(name, value)
        else:
            self.datamodel.declare(name.strip(), value)

    def content_value(self, content: Content) -> Any:
        if content.expr is not None:
            return self.datamodel.evaluate(content.expr)
        return inline_value(content.body or "")

    def params_value(self, namelist: Iterable[str], params: Iterable[Param]) -> EventData:
        dm = self.datamodel
        data = EventData()
        for name in namelist:
            if not dm.is_location(name):
                raise EvaluationError(f"namelist entry {name!r} is not a declared location")
            data[name] = dm.evaluate(name)
        for p in params:
            if p.expr is not None:
                data[p.name] = dm.evaluate(p.expr)
            elif p.location is not None:
                if not dm.is_location(p.location):
                    raise EvaluationError(f"param location {p.location!r} is not declared")
                data[p.name] = dm.evaluate(p.location)
        return data

    def new_id(self, prefix: str) -> str:
        return f"{prefix}.{self.sessionid[:8]}.{next(self._ids)}"

    def send(self, s: Send) -> None:
        sending.send(self, s)

    def route(self, target: str | None, event: Event, sendid: str) -> Callable[[], None] | None:
        """Where a send goes, as a function that delivers it; errors are raised here."""
        return sending.route(self, target, event, sendid)

    def check_invoke_bounds(self) -> None:
        sending.check_invoke_bounds(self)

    def invoke(self, state: str, d: ChildInvoke) -> None:
        sending.invoke(self, state, d)
