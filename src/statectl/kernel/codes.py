"""Every diagnostic code statectl reports, in one registry.

A :class:`~statectl.kernel.errors.Diagnostic` carries a bare code such as ``"C401"``; this module
says what each code means: its default severity, a one-line summary and the docs page
and anchor that explain it. Modules keep creating ``Diagnostic(code, ...)`` as before;
their ``CODES`` tables (``statectl.front.rules.CODES``, ``statectl.front.tables.CODES``, ...) are
views of this registry, and ``tests/test_codes.py`` holds the source, the registry and
the docs to one another. Standard library only, beside :mod:`statectl.kernel.errors` in the
kernel ring, so any layer may import it.

Families: T1xx tables, B2xx build, X3xx expressions, C4xx check rules, D5xx driver and
run configs, S6xx SCXML, J6xx Recovery table, G7xx C++ codegen, V8xx cells.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from statectl.kernel.errors import Severity, StatectlError

__all__ = ["ALL", "REGISTRY", "Code", "UnknownCodeError", "explain", "family", "lookup"]

_E, _W, _I = Severity.ERROR, Severity.WARNING, Severity.INFO


@dataclass(frozen=True, slots=True)
class Code:
    """One diagnostic code: what it means and where the docs explain it.

    ``severity`` is the severity the code is normally raised at; ``also`` lists the
    others a caller may use (C403 is a warning for guarded rows, J606 a warning in a
    journalled run). ``page`` is relative to the repository root; ``anchor`` is the
    GitHub-style id of the heading whose section explains the code.
    """

    code: str
    severity: Severity
    summary: str
    page: str
    anchor: str
    also: tuple[Severity, ...] = ()

    @property
    def doc(self) -> str:
        """``page#anchor``, as a link."""
        return f"{self.page}#{self.anchor}"

    @property
    def severities(self) -> frozenset[Severity]:
        return frozenset((self.severity, *self.also))


_TABLES = ("docs/tables.md", "diagnostics")
_SCXML = ("docs/scxml.md", "diagnostics")
_CODEGEN = ("docs/codegen.md", "diagnostics")
_CELLS = ("docs/cells.md", "diagnostics")
_DRIVERS = ("docs/runtime.md", "drivers-and-their-configuration")
_BUS = ("docs/drivers.md", "configuration-diagnostics")
_NODES = ("docs/distributed.md", "diagnostics")
_BUILDER = ("docs/check.md", "builder-codes-reported-through-check")


def _c(
    code: str,
    severity: Severity,
    summary: str,
    doc: tuple[str, str],
    also: tuple[Severity, ...] = (),
) -> Code:
    return Code(code, severity, summary, doc[0], doc[1], also)


def _check(anchor: str) -> tuple[str, str]:
    return ("docs/check.md", anchor)


#: Every code, in family and number order. A code appears exactly once.
ALL: tuple[Code, ...] = (
    # -- T1xx: reading device tables (statectl.front.tables) ------------------------------------
    _c("T101", _E, "malformed file (YAML, CSV, XLSX or Markdown syntax)", _TABLES),
    _c("T102", _E, "not a device file, or the wrong top-level type", _TABLES),
    _c("T103", _E, "unknown column", _TABLES),
    _c("T104", _E, "missing required column, key or cell", _TABLES),
    _c("T105", _E, "empty table", _TABLES),
    _c("T106", _E, "bad control value", _TABLES),
    _c("T107", _E, "bad kind value", _TABLES),
    _c("T108", _E, "wrong cell type (e.g. a mapping where text is expected)", _TABLES),
    _c("T109", _E, "state rows for one state that contradict each other", _TABLES),
    _c("T110", _E, "file not found, unreadable or not writable", _TABLES),
    _c("T111", _E, "an event name contains a comma", _TABLES),
    _c("T112", _E, "bad data entry (name not an identifier, or given twice)", _TABLES),
    _c(
        "T113",
        _E,
        "bad type value (none of atomic, compound, parallel, final, history, deep history)",
        _TABLES,
    ),
    _c(
        "T114",
        _E,
        "bad recovery row (both an event and redo, data on a redo row, or a bad redo value)",
        _TABLES,
    ),
    _c("T115", _E, "a YAML alias (*name): refused, so an alias bomb cannot expand", _TABLES),
    _c("T116", _E, "YAML nested deeper than the limit (MAX_DEPTH): see docs/limits.md", _TABLES),
    _c(
        "T117",
        _E,
        "a workbook that unpacks to more than the limit (a zip bomb): see docs/limits.md",
        _TABLES,
    ),
    _c(
        "T118",
        _E,
        "a timeout cell that is not DURATION -> EVENT (unit ms, s or min; 1 ms to 2^31-1 ms)",
        _TABLES,
    ),
    _c("T122", _E, "a bad event data declaration (data column: 'name: type, ...')", _TABLES),
    _c("T123", _E, "a bad assign cell ('name = expression; ...')", _TABLES),
    _c("T124", _E, "an XLSX formula cell with no saved value (read it would be empty)", _TABLES),
    _c(
        "T125",
        _E,
        "a bad unasked cell (not yes, no, true or false; or on an event that is not a completion)",
        _TABLES,
    ),
    _c(
        "T126",
        _E,
        "a bad severity cell (not a whole number from 1 to 1000; or on an event that is not "
        "a fault)",
        _TABLES,
    ),
    # -- B2xx: building a chart from tables, and tables from a chart (front.builder.build) --
    _c("B201", _E, "an event row's old or new state is not in the State Definition table", _TABLES),
    _c("B202", _E, "no state is marked default", _TABLES),
    _c("B203", _E, "several states are marked default at one level", _TABLES),
    _c("B204", _I, "identical event rows merged into one transition", _TABLES),
    _c("B205", _I, "several rows for one state merged", _TABLES),
    _c("B206", _E, "rows for one event disagree on kind or API", _TABLES),
    _c("B207", _W, "a state without control that no event touches was removed", _TABLES),
    _c("B208", _E, "an ignore cell names an unknown event", _TABLES),
    _c("B209", _E, "a parent names an unknown state", _TABLES),
    _c("B210", _E, "parents form a cycle", _TABLES),
    _c("B211", _E, "one API has two explicit invoke names", _TABLES),
    _c(
        "B212",
        _E,
        "a history state at the top, with children or a control, or a default outside",
        _TABLES,
    ),
    _c("B213", _E, "a final state with children", _TABLES),
    _c("B214", _E, "a parallel state with fewer than two regions", _TABLES),
    _c(
        "B215",
        _E,
        "a type that contradicts the rows (atomic with children, compound without)",
        _TABLES,
    ),
    _c("B216", _E, "an event row leaves a history or a final state", _TABLES),
    _c("B217", _E, "a default cell on a state that is not a history", _TABLES),
    _c("B218", _E, "states nested deeper than the limit (MAX_STATE_DEPTH)", _TABLES),
    _c(
        "B220",
        _I,
        "a chart with executable content, datamodel scripts or non-literal data does not "
        "fit the tables",
        _TABLES,
    ),
    _c(
        "B221",
        _I,
        "a transition the tables cannot hold: eventless, several events or targets, "
        "targetless or internal",
        _TABLES,
    ),
    _c("B222", _I, "a guard outside the safe expression language does not fit the tables", _TABLES),
    _c("B223", _I, "the tables made from a chart would not build the same chart", _TABLES),
    _c("B236", _E, "a state number that is not a whole number from 0 to 2**31 - 1", _TABLES),
    _c("B237", _E, "two states of one device with the same number", _TABLES),
    _c("B224", _E, "a state's timeout names an event that is not in the events table", _TABLES),
    _c("B225", _E, "a timeout or defer on a history or final state (never active)", _TABLES),
    _c("B226", _E, "a defer cell names an event that is not in the events table", _TABLES),
    _c("B227", _E, "a state defers an event it (or an ancestor) handles", _TABLES),
    _c("B228", _W, "a state's api names a method no event entering or leaving it uses", _TABLES),
    _c("B230", _E, "rows for one event declare different data", _TABLES),
    _c(
        "B231",
        _E,
        "event data read with a spelling that cannot work (_event.data.NAME does)",
        _TABLES,
    ),
    _c("B232", _E, "a guard or assignment reads a field the event does not declare", _TABLES),
    _c("B233", _W, "a guard or assignment reads data of an event that declares none", _TABLES),
    _c("B234", _E, "an assignment to a name that is not a data item", _TABLES),
    _c("B235", _E, "identical event rows that disagree on their assignments", _TABLES),
    # -- X3xx: the safe expression language (statectl.kernel.expr, scxml.safecheck) --------------
    _c("X301", _E, "an expression does not parse (or is nested too deeply to analyse)", _BUILDER),
    _c("X302", _E, "an expression uses something the safe expression language refuses", _BUILDER),
    _c("X303", _E, "an expression reads an undefined name", _BUILDER),
    _c("X304", _E, "a literal part of an expression would exceed a bound", _BUILDER),
    _c("X305", _E, "an expression is too long or nested too deeply", _BUILDER),
    _c(
        "X306",
        _E,
        "a declared event data field compared with a literal of another type",
        _BUILDER,
    ),
    # -- C4xx: statectl check's rules (statectl.front.rules) ------------------------------------
    _c("C401", _E, "unreachable state", _check("c401--unreachable-state-error")),
    _c("C402", _W, "state with no way out", _check("c402--state-with-no-way-out-warning")),
    _c(
        "C403",
        _E,
        "two rows for the same state and event may both fire",
        _check("c403--two-rows-may-both-fire-error-or-warning"),
        also=(_W,),
    ),
    _c(
        "C404",
        _W,
        "event neither handled nor ignored by a state (missed transition)",
        _check("c404--missed-transition-warning"),
    ),
    _c(
        "C405",
        _W,
        "event declared but used by no transition",
        _check("c405--unused-event-warning"),
    ),
    _c(
        "C406",
        _W,
        "ignore entry for an event the state handles",
        _check("c406--contradictory-ignore-warning"),
    ),
    _c(
        "C407",
        _W,
        "monitoring-required state with no fault event leaving it",
        _check("c407--monitor-with-nothing-to-raise-warning"),
    ),
    _c(
        "C408",
        _W,
        "fault event leaving a state that is not monitoring required",
        _check("c408--fault-without-a-monitor-warning"),
    ),
    _c(
        "C418",
        _W,
        "the device declares a profile statectl does not ship",
        _check("c418--unknown-profile-warning"),
    ),
    _c(
        "C409",
        _E,
        "a state's timeout event is not handled in that state",
        _check("c409--unhandled-timeout-error"),
    ),
    _c(
        "C410",
        _W,
        "a deferred event is released into a state that neither handles, defers nor ignores it",
        _check("c410--deferred-event-dropped-warning"),
    ),
    _c(
        "C411",
        _W,
        "an 'event trigger required' state that no command or fault event enters",
        _check("c411--trigger-state-entered-by-no-command-warning"),
    ),
    # C415-C416: a file of the other kind (statectl.front.kinds)
    _c(
        "C415",
        _E,
        "a cell file given to check: use verify",
        _check("c415--a-cell-file-given-to-check-error"),
    ),
    _c(
        "C416",
        _E,
        "a device file given to verify: use check",
        _check("c416--a-device-file-given-to-verify-error"),
    ),
    _c("C412", _E, "verify: a device's assigned data does not stay bounded", _CELLS),
    _c(
        "C419",
        _W,
        "the guards of a state's rows for one event may all be false",
        _check("c419--guards-that-may-leave-an-event-unhandled-warning"),
    ),
    _c(
        "C420",
        _E,
        "a guard names a state the device does not have (In(), previous)",
        _check("c420--a-guard-names-a-state-the-device-does-not-have-error"),
    ),
    _c(
        "C421",
        _E,
        "a guard compares _event.name with an event the device does not have",
        _check("c421--a-guard-names-an-event-the-device-does-not-have-error"),
    ),
    _c(
        "C422",
        _W,
        "a completion answers no call: the twin never reports it, verify never offers it",
        _check("c422--a-completion-that-answers-no-call-warning"),
    ),
    _c(
        "C413",
        _E,
        "a recovery rule's data does not fit the fields its event declares",
        _check("c413--recovery-data-its-event-would-refuse-error"),
    ),
    # -- D5xx: driver and run configs (statectl.channels.runconfig and its sections' owners) --
    _c("D501", _E, "the driver or run config cannot be read", _DRIVERS),
    _c("D502", _E, "the config is not valid YAML (or an alias or too deep)", _DRIVERS),
    _c("D503", _E, "no 'devices' mapping", _DRIVERS),
    _c("D504", _E, "a device entry is not a mapping or has no 'driver'", _DRIVERS),
    _c("D505", _E, "an unknown or unusable driver", _DRIVERS),
    _c("D506", _E, "a device's 'options' is not a mapping", _DRIVERS),
    _c("D507", _E, "an unknown key", _DRIVERS),
    _c("D508", _E, "an option the driver does not take", _DRIVERS),
    _c("D509", _E, "an option value the driver refuses", _DRIVERS),
    _c("D510", _E, "a bad 'dashboard:' section", _DRIVERS),
    _c("D511", _E, "a bus driver option value it refuses (address, port, node id, EDS)", _BUS),
    _c("D512", _E, "a bus driver whose library is not installed", _BUS),
    _c("D520", _E, "a bad 'opcua:' section", ("docs/opcua.md", "configuration")),
    _c("D530", _E, "a bad 'ship:' section", ("docs/journal.md", "shipping-to-postgresql")),
    _c(
        "D540",
        _E,
        "a bad 'commands:' section",
        ("docs/runtime.md", "who-may-command-the-commands-section"),
    ),
    # -- S6xx: reading SCXML (statectl.out.scxml.reader) --------------------------------------
    _c("S601", _E, "the document is not well-formed XML", _SCXML),
    _c("S602", _E, "the root is not <scxml> in the SCXML namespace", _SCXML),
    _c(
        "S603",
        _E,
        "a required attribute is missing or a statectl: value is unknown",
        _SCXML,
        also=(_W,),
    ),
    _c("S604", _E, "a state id is used twice", _SCXML),
    _c("S605", _E, "a transition, initial or history default names an unknown state", _SCXML),
    _c("S606", _W, "an unknown element in executable content (skipped)", _SCXML),
    _c("S607", _E, "a file (the document or a src) cannot be read or is refused", _SCXML),
    _c("S620", _E, "elements nested deeper than the limit (MAX_XML_DEPTH)", _SCXML),
    _c("S621", _E, "an encoding the document declares cannot be read", _SCXML),
    _c("S622", _E, "the DTD declares an entity: refused", _SCXML),
    _c("S623", _E, "a <statectl:recovery> element that is no valid Recovery row", _SCXML),
    _c("S624", _E, "(export) a state name holds whitespace, which no SCXML id can", _SCXML),
    # -- J6xx: the Recovery table against its chart (statectl.front.recovery) -------------------
    _c(
        "J603",
        _E,
        "a recovery rule names a state the chart does not have",
        _check("j603--recovery-rule-for-an-unknown-state-error"),
    ),
    _c(
        "J604",
        _E,
        "a recovery rule's event does not leave its state by any transition",
        _check("j604--recovery-event-does-not-leave-its-state-error"),
    ),
    _c(
        "J605",
        _E,
        "two recovery rules for one state",
        _check("j605--two-recovery-rules-for-one-state-error"),
    ),
    _c(
        "J606",
        _I,
        "a monitored state has no recovery rule",
        _check("j606--monitored-state-without-a-recovery-rule-info-warning-in-a-journalled-run"),
        also=(_W,),
    ),
    _c(
        "J607",
        _E,
        "a redo rule for a state no transition enters with a device API call",
        _check("j607--nothing-to-redo-error"),
    ),
    _c(
        "J608",
        _I,
        "a state left only by completion events has no recovery rule",
        _check(
            "j608--state-that-waits-for-its-device-without-a-recovery-rule-info-warning-in-a-"
            "journalled-run"
        ),
        also=(_W,),
    ),
    # -- G7xx: flattening a chart for C++ (statectl.out.codegen.flatten) ----------------------
    _c(
        "G701",
        _E,
        "executable content the generated code cannot perform (Script, Assign, Send, ...)",
        _CODEGEN,
    ),
    _c("G702", _E, "a guard that does not translate to C++", _CODEGEN),
    _c("G703", _E, "a guard reads _event (event data does not exist in generated code)", _CODEGEN),
    _c("G704", _E, "a guard reads a context field that is not an integer", _CODEGEN),
    _c("G705", _E, "a datamodel other than 'safe'", _CODEGEN),
    _c("G706", _E, "too many configurations or guard paths for flat tables", _CODEGEN),
    _c("G707", _E, "a step that does not settle (livelock) or fails in the semantics", _CODEGEN),
    _c("G708", _W, "a Log action the generated code skips", _CODEGEN),
    _c("G709", _E, "a Notify of an invoke number the chart does not declare", _CODEGEN),
    _c("G710", _E, "a state's timeout names an event the chart does not know", _CODEGEN),
    _c("G711", _E, "a timeout that is not a whole number of milliseconds (1 to 2^31-1)", _CODEGEN),
    _c("G712", _E, "a timeout on a state past the timeout table's index (32768 states)", _CODEGEN),
    _c("G713", _E, "an assignment the generated code cannot perform", _CODEGEN),
    _c("G714", _E, "a guard that fails when the semantics evaluates it", _CODEGEN),
    # -- V8xx: cell files (statectl.cell.model) -------------------------------------------------
    _c("V801", _E, "the cell file cannot be read or is not a YAML mapping", _CELLS),
    _c("V802", _E, "an unknown key", _CELLS),
    _c("V803", _E, "a required key is missing", _CELLS),
    _c("V804", _E, "a value has the wrong shape (text, list or mapping expected)", _CELLS),
    _c("V805", _E, "a device file does not load", _CELLS),
    _c("V806", _E, "a device instance name is invalid or used twice", _CELLS),
    _c("V807", _E, "a rule names an unknown device", _CELLS),
    _c("V808", _E, "a rule names a state the device does not have", _CELLS),
    _c("V809", _E, "a rule names an event the device does not know", _CELLS),
    _c("V810", _E, "a global expression uses something other than In(), and, or, not", _CELLS),
    _c("V811", _E, "In() does not name 'device.State'", _CELLS),
    _c(
        "V812",
        _E,
        "an environment fault is not a fault event, or the device has no monitored state",
        _CELLS,
        also=(_W,),
    ),
    _c("V813", _E, "a link needs exactly one of 'enters' and 'raises'", _CELLS),
    _c("V814", _E, "two invariants or recovery goals share a name", _CELLS),
    _c("V815", _E, "the cell has no devices", _CELLS),
    _c("V830", _E, "a link's event data does not read, or is given twice", _CELLS),
    _c(
        "V831",
        _E,
        "a device guard's In('device.State') names no device or state of the cell",
        _CELLS,
    ),
    # V820-V829: the nodes: section (statectl.cell.nodes), docs/distributed.md
    _c("V820", _E, "a device runs on no node, or on two", _NODES),
    _c("V821", _E, "a node name is not an identifier or is used twice", _NODES),
    _c("V822", _E, "a node endpoint is not PROTOCOL/HOST:PORT", _NODES),
    _c("V823", _E, "a link's on_peer_down is not queue or drop", _NODES),
    _c("V824", _E, "a link's dropped event without on_peer_down: drop", _NODES),
    _c("V825", _E, "a node's peer_lost names a device that does not run on it", _NODES),
    _c("V826", _W, "on_peer_down or dropped in a cell without nodes:", _NODES),
    _c("V827", _E, "a node endpoint off loopback without TLS (and no insecure: true)", _NODES),
    _c("V828", _E, "the security: section cannot hold (files, posts, stations, endpoints)", _NODES),
)

#: Code -> record, read-only.
REGISTRY: Mapping[str, Code] = MappingProxyType({c.code: c for c in ALL})


class UnknownCodeError(StatectlError, KeyError):
    """A code that is not in the registry."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


def lookup(code: str) -> Code:
    """The record of ``code`` (case-insensitive); :class:`UnknownCodeError` if none."""
    found = REGISTRY.get(code.strip().upper())
    if found is None:
        close = difflib.get_close_matches(code.strip().upper(), REGISTRY, n=3)
        hint = f"; did you mean {', '.join(close)}?" if close else ""
        raise UnknownCodeError(f"unknown diagnostic code {code!r}{hint}")
    return found


def family(*prefixes: str) -> Mapping[str, str]:
    """Code -> summary for every code starting with one of ``prefixes``, read-only.

    The modules' ``CODES`` tables are these views, e.g. ``family("C4")``.
    """
    return MappingProxyType({c.code: c.summary for c in ALL if c.code.startswith(prefixes)})


def explain(code: str) -> str:
    """A few lines on ``code`` for ``statectl check --explain CODE``.

    Raises :class:`UnknownCodeError` (a :class:`StatectlError`) for a code that is not
    registered, naming the closest ones.
    """
    c = lookup(code)
    severity = c.severity.value
    if c.also:
        severity += " (or " + ", ".join(s.value for s in c.also) + ")"
    return f"{c.code} {severity}: {c.summary}\nsee {c.doc}\n"
