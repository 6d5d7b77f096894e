"""Whether a device's step fires a cell's links, and what each sends: the one answer.

verify (:mod:`statectl.cell.explore.compose`), ``statectl run CELL`` and the System
(:class:`statectl.cell.explore.replay.CellLinks`) and a node over Zenoh
(:mod:`statectl.channels.distributed.system`) all ask this module, so what verify
proves about links is what runs. Pure: no I/O, no runtime.

Rules:
1. A step is the kernel's :class:`~statectl.kernel.semantics.Step`: microsteps, each
   with the event it took transitions on (``None``: eventless) and the states it
   entered. A step that did not handle its event took no microstep and fires nothing.
2. ``enters S`` fires when some microstep of the source device's step entered ``S``.
3. ``raises E`` fires when some microstep of the source device's step took a
   transition on ``E``: the external event, or an event the device raised itself
   during the step (``done.state.*``, an SCXML ``<raise>``). A transition on ``E``
   is one wherever ``E`` came from (docs/cells.md).
4. A link fires at most once per step, however many microsteps match; fired links
   come in the cell file's order.
5. A fired link sends only if its guard (if any) holds in the global state after the
   step. The state is asked for only when a fired link has a guard.
6. It sends its event to its target with its own data, or with the data of the event
   whose step fired it (``forward_data``).
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Sequence, Sized
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from statectl.cell.values import Link, Trigger

__all__ = ["CellLinkRules", "Micro", "Send", "Triggers", "sent_data", "triggers"]

S = TypeVar("S")
#: steps whose fired links are kept (:meth:`CellLinkRules.fired`); then the memo starts over
_SEEN_MAX = 4096


class Micro(Protocol):
    """One microstep as links read it: the kernel's ``Microstep`` or a runtime
    ``MicrostepTaken`` record (a step a failing observer cut short is read that way)."""

    @property
    def event(self) -> str | None: ...
    @property
    def transitions(self) -> Sized: ...
    @property
    def entered(self) -> Collection[str]: ...


@dataclass(frozen=True, slots=True)
class Triggers:
    """What a step offers links (rule 1): the states it entered, the events it took."""

    entered: frozenset[str]
    events: frozenset[str]


@dataclass(frozen=True, slots=True)
class Send:
    """One fired link's delivery (rule 6): ``event`` with ``data`` to ``target``."""

    link: int  # index in the cell's links
    target: str
    event: str
    data: Any


def triggers(microsteps: Iterable[Micro]) -> Triggers:
    """Rules 1-3: the states ``microsteps`` entered and the events they took transitions on."""
    entered: set[str] = set()
    events: set[str] = set()
    for m in microsteps:
        entered.update(m.entered)
        if m.event is not None and len(m.transitions):
            events.add(m.event)
    return Triggers(frozenset(entered), frozenset(events))


def sent_data(link: Link, data: Any) -> Any:
    """Rule 6: the data ``link`` sends when the event of the step that fired it had ``data``."""
    return data if link.forward_data else link.data


class CellLinkRules:
    """A cell's links compiled for the question: per source, which state or event fires which."""

    def __init__(self, links: Sequence[Link]) -> None:
        self.links = tuple(links)
        self._enters: dict[str, dict[str, list[int]]] = {}
        self._raises: dict[str, dict[str, list[int]]] = {}
        for i, k in enumerate(self.links):
            table = self._enters if k.trigger is Trigger.ENTERS else self._raises
            table.setdefault(k.source, {}).setdefault(k.what, []).append(i)
        self.sources = frozenset(k.source for k in self.links)
        self._seen: dict[tuple[str, int], tuple[tuple[Micro, ...], tuple[int, ...]]] = {}

    def matching(self, source: str, found: Triggers) -> tuple[int, ...]:
        """Rules 2-4: the links a step of ``source`` that offers ``found`` fires."""
        out: set[int] = set()
        for table, offered in ((self._enters, found.entered), (self._raises, found.events)):
            whats = table.get(source)
            if whats:
                for what in offered:
                    out.update(whats.get(what, ()))
        return tuple(sorted(out))

    def fired(self, source: str, microsteps: Iterable[Micro]) -> tuple[int, ...]:
        """Rules 1-4 for a step of ``source`` given as its microsteps.

        The kernel hands out one ``Step`` per plan, so a step's microsteps repeat as
        the same tuple: its answer is kept (with the tuple, so its id is not reused).
        """
        if source not in self.sources:
            return ()
        if type(microsteps) is not tuple:
            return self.matching(source, triggers(microsteps))
        key = (source, id(microsteps))
        hit = self._seen.get(key)
        if hit is not None and hit[0] is microsteps:
            return hit[1]
        found = self.matching(source, triggers(microsteps))
        if len(self._seen) >= _SEEN_MAX:
            self._seen.clear()
        self._seen[key] = (microsteps, found)
        return found

    @staticmethod
    def holding(
        fired: Iterable[int], guards: Sequence[Callable[[S], bool] | None], state: Callable[[], S]
    ) -> tuple[int, ...]:
        """Rule 5: the links of ``fired`` whose guard holds in ``state()`` (asked once, and
        only if one of them has a guard)."""
        out: list[int] = []
        now: list[S] = []
        for i in fired:
            guard = guards[i]
            if guard is not None:
                if not now:
                    now.append(state())
                if not guard(now[0]):
                    continue
            out.append(i)
        return tuple(out)

    def send(self, i: int, data: Any) -> Send:
        """Rule 6: what link ``i`` sends when the event that fired it had ``data``."""
        k = self.links[i]
        return Send(i, k.target, k.event, sent_data(k, data))

    def fire(
        self,
        source: str,
        microsteps: Iterable[Micro],
        guards: Sequence[Callable[[S], bool] | None],
        state: Callable[[], S],
        data: Any = None,
    ) -> tuple[Send, ...]:
        """Rules 1-6 at once: what a step of ``source`` sends over the links."""
        fired = self.fired(source, microsteps)
        return tuple(self.send(i, data) for i in self.holding(fired, guards, state))
