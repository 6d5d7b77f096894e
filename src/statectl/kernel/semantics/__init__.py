"""The pure kernel: what happens when an event meets a configuration.

Follows the algorithm of the W3C SCXML recommendation (Appendix D) and names its
parts after it, so the pseudocode can be read beside this file. Rules:

1. :func:`initial` and :func:`step` return a :class:`Step` that *describes* the
   exit set, the transitions taken, the entry set and the actions to perform;
   nothing is performed here (no observer is called, no clock is read).
2. A step is one macrostep: the external event's microstep, then eventless
   transitions and internally raised events (``Raise``, ``done.state.*``) until
   the configuration is stable, which is run-to-completion.
3. Transition selection is in document order of the active atomic states; a
   state's own transitions before its ancestors'; conflicts are resolved by
   :func:`remove_conflicting_transitions` (a descendant's transition preempts).
4. A chart is compiled once (:class:`Machine`): ancestors, descendants,
   candidate transitions per (state, event), static transition domains and
   compiled guards. Where no guard was consulted a step depends only on
   ``(snapshot, event)`` and is memoised, so dispatch is close to a lookup.
   A memoised step of a declared event is also kept as a :class:`Plan` in the
   plan table of its (interned) source snapshot; a plan points at its target's
   table, so a host walks from table to table with one dictionary lookup per
   event. Plans are decisions too: the host still performs them.
5. A host that runs executable content (the SCXML session) drives the same
   functions one microstep at a time through a :class:`Run` that carries an
   :class:`Executor`. The executor evaluates conditions and performs content at
   the spec's points, in order: each exited state's onexit, the transitions'
   content, then per entered state its onentry, initial and history content, and
   the ``done.state`` events. Events it raises go straight to the internal queue,
   so the queue order is the spec's. Without an executor, ``Raise`` is the only
   content the kernel acts on (it queues the event at once); the rest is returned.
"""

from statectl.kernel.semantics.algorithm import (
    compute_entry_set,
    compute_exit_set,
    condition_match,
    enter_initial_states,
    entry_set,
    exit_interpreter,
    get_transition_domain,
    guard_env,
    macrostep,
    microstep,
    process_event,
    remove_conflicting_transitions,
    select_eventless_transitions,
    select_transitions,
)
from statectl.kernel.semantics.machine import (
    Machine,
    compiled,
    name_match,
    release,
    structural,
)
from statectl.kernel.semantics.records import (
    MAX_GUARD_PATHS,
    MAX_MICROSTEPS,
    MEMO_LIMIT,
    Consult,
    Event,
    Executor,
    GuardOracle,
    LivelockError,
    Microstep,
    Outcome,
    Plan,
    PlanTable,
    Run,
    Snapshot,
    Step,
    Unhandled,
)
from statectl.kernel.semantics.stepping import initial, initial_data, step, unhandled_reason

__all__ = [
    "MAX_GUARD_PATHS",
    "MAX_MICROSTEPS",
    "MEMO_LIMIT",
    "Consult",
    "Event",
    "Executor",
    "GuardOracle",
    "LivelockError",
    "Machine",
    "Microstep",
    "Outcome",
    "Plan",
    "PlanTable",
    "Run",
    "Snapshot",
    "Step",
    "Unhandled",
    "compiled",
    "compute_entry_set",
    "compute_exit_set",
    "condition_match",
    "enter_initial_states",
    "entry_set",
    "exit_interpreter",
    "get_transition_domain",
    "guard_env",
    "initial",
    "initial_data",
    "macrostep",
    "microstep",
    "name_match",
    "process_event",
    "release",
    "remove_conflicting_transitions",
    "select_eventless_transitions",
    "select_transitions",
    "step",
    "structural",
    "unhandled_reason",
]
