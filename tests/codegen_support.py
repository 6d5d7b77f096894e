"""Shared helpers of the codegen tests: the Python reference trace and the C++ driver.

The canonical trace is one line per record, the same words on both backends:
``start``, ``event E``, ``exit S``, ``take S -> T on LABEL``, ``enter S``,
``invoke N``, ``api METHOD``, ``ignored E (REASON)``, ``finished`` and, after
the last event of a sequence, ``config S1, S2`` (active states in document order).
"""

from __future__ import annotations

import difflib
import shutil
import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pytest

from statectl.front.observers import Notification
from statectl.kernel.errors import Diagnostic, Severity, has_errors
from statectl.kernel.model import Chart
from statectl.out.codegen.cpp import render, runtime_files
from statectl.out.codegen.cpp_names import identifiers
from statectl.out.codegen.cpp_rows import DENSE_CELLS
from statectl.out.codegen.flatten import flatten
from statectl.run.runtime import SimClock, Subject
from statectl.run.runtime.records import (
    EventIgnored,
    EventReceived,
    Finished,
    InvokeIssued,
    MicrostepTaken,
    Started,
)

GXX = shutil.which("g++")
CLANG = shutil.which("clang++")
FLAGS = ("-std=c++17", "-Wall", "-Wextra", "-Wpedantic", "-Werror", "-fno-exceptions", "-fno-rtti")
needs_gxx = pytest.mark.skipif(GXX is None, reason="no g++ on this machine")

#: One sequence: context values (field name -> int) and the events to post.
Sequence_ = tuple[Mapping[str, int], Sequence[str]]


def canonical(record: object) -> list[str]:
    """The canonical lines of one record (a microstep is a line per exit, transition
    and entry, in that order); none for a record the C++ trace has no line for."""
    match record:
        case Started():
            return ["start"]
        case EventReceived(event=event):
            return [f"event {event}"]
        case MicrostepTaken(exited=exited, transitions=transitions, entered=entered):
            return [
                *[f"exit {s}" for s in exited],
                *[f"take {t.source} -> {', '.join(t.targets)} on {t.label}" for t in transitions],
                *[f"enter {s}" for s in entered],
            ]
        case InvokeIssued(invoke=invoke):
            return [f"invoke {invoke}"]
        case EventIgnored(event=event, reason=reason):
            return [f"ignored {event} ({reason})"]
        case Finished():
            return ["finished"]
    return []


class _Recorder:
    """An observer that writes ``api METHOD`` into the trace when notified."""

    def __init__(self, lines: list[str]) -> None:
        self.lines = lines

    def update(self, notification: Notification) -> None:
        self.lines.append(f"api {notification.method}")


def python_trace(chart: Chart, context: Mapping[str, Any], events: Sequence[str]) -> list[str]:
    """The reference: statectl's own runtime (Subject over semantics.step)."""
    lines: list[str] = []
    subject = Subject(chart, clock=SimClock(), data=dict(context))
    if chart.invokes:
        subject.attach(_Recorder(lines))

    def listen(record: object) -> None:
        lines.extend(canonical(record))

    subject.listen(listen)
    subject.start()
    for e in events:
        subject.post(e)
        subject.run_until_idle()
    order = [s.name for s in chart.states]
    lines.append("config " + ", ".join(s for s in order if s in subject.configuration))
    return lines


_DRIVER = r"""
#include "@BASE@.hpp"

#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace {

class PrintTracer final : public statectl::Tracer {
 public:
  void started(const char*) noexcept override { std::puts("start"); }
  void event(const char*, const char* e) noexcept override { std::printf("event %s\n", e); }
  void exited(const char*, const char* s) noexcept override { std::printf("exit %s\n", s); }
  void taken(const char*, const char* s, const char* t, const char* l) noexcept override {
    std::printf("take %s -> %s on %s\n", s, t, l);
  }
  void entered(const char*, const char* s) noexcept override { std::printf("enter %s\n", s); }
  void invoked(const char*, int n, const char*, const char*) noexcept override {
    std::printf("invoke %d\n", n);
  }
  void ignored(const char*, const char* e, const char* r) noexcept override {
    std::printf("ignored %s (%s)\n", e, r);
  }
  void finished(const char*) noexcept override { std::puts("finished"); }
};

class PrintApi final : public @NS@::@CLS@Api {
 public:
@METHODS@
};

}  // namespace

// stdin: one sequence per line, "v1 v2 ... ; e1 e2 ..." (context values, event indices).
int main() {
  static char line[65536];
  while (std::fgets(line, sizeof line, stdin) != nullptr) {
    @NS@::@CLS@ device;
    PrintTracer tracer;
    PrintApi api;
    device.set_tracer(&tracer);
@ATTACH@
    char* p = line;
    char* end = nullptr;
    long values[64];
    int n = 0;
    while (*p != ';' && *p != '\0') {
      long v = std::strtol(p, &end, 10);
      if (end == p) { ++p; continue; }
      values[n++] = v;
      p = end;
    }
    static_cast<void>(values);
@ASSIGN@
    device.start();
    if (*p == ';') ++p;
    for (;;) {
      long e = std::strtol(p, &end, 10);
      if (end == p) break;
      device.dispatch(static_cast<@NS@::Event>(e));
      p = end;
    }
    std::printf("config ");
    const char* sep = "";
    for (std::size_t s = 0; s < @NS@::kStateCount; ++s) {
      if (device.in(static_cast<@NS@::State>(s))) {
        std::printf("%s%s", sep, @NS@::detail::kStateNames[s]);
        sep = ", ";
      }
    }
    std::printf("\n---\n");
  }
  return 0;
}
"""


def driver_source(chart: Chart, fields: Sequence[str], field_idents: Mapping[str, str]) -> str:
    cls = identifiers([chart.name])[chart.name]
    ns = identifiers([chart.name], lower=True)[chart.name]
    invokes = sorted(chart.invokes, key=lambda i: i.number)
    methods = identifiers([i.method for i in invokes])
    method_text = "\n".join(
        f'  void {methods[i.method]}() noexcept override {{ std::puts("api {i.method}"); }}'
        for i in invokes
    )
    attach = "\n".join(f"    device.attach(api, {ns}::Invoke({i.number}));" for i in invokes)
    assign = "\n".join(
        f"    if (n > {k}) device.context.{field_idents[f]} = values[{k}];"
        for k, f in enumerate(fields)
    )
    return (
        _DRIVER.replace("@BASE@", ns)
        .replace("@NS@", ns)
        .replace("@CLS@", cls)
        .replace("@METHODS@", method_text)
        .replace("@ATTACH@", attach or "    (void)api;")
        .replace("@ASSIGN@", assign)
    )


class Refused(Exception):
    """The generator refused the chart; ``diagnostics`` say why (G7xx errors)."""

    def __init__(self, diagnostics: Sequence[Diagnostic]) -> None:
        super().__init__("; ".join(str(d) for d in diagnostics))
        self.diagnostics = tuple(diagnostics)


class CppDevice:
    """A chart generated and compiled once, run over many sequences in one process.

    Raises :class:`Refused` when the generator reports an error, so a caller can
    tell a refusal (a diagnostic) from a crash (any other exception).
    """

    def __init__(
        self,
        chart: Chart,
        workdir: Path,
        compiler: str | None = None,
        dense_limit: int = DENSE_CELLS,
    ) -> None:
        self.chart = chart
        flat, diags = flatten(chart)  # once: generating re-flattens otherwise
        if flat is None or has_errors(diags):
            raise Refused([d for d in diags if d.severity is Severity.ERROR])
        for rel, text in {**render(flat, dense_limit), **runtime_files()}.items():
            path = workdir / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
        self.fields = [f.name for f in flat.context]
        idents = {f.name: f.ident for f in flat.context}
        self.events = list(flat.events)
        (workdir / "driver.cpp").write_text(driver_source(chart, self.fields, idents))
        self.binary = workdir / "driver"
        cmd = [
            compiler or GXX or "g++",
            *FLAGS,
            "-O0",
            "-DSTATECTL_TRACE=1",
            "-I",
            str(workdir),
            str(workdir / "driver.cpp"),
            "-o",
            str(self.binary),
        ]
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        assert done.returncode == 0, done.stderr

    def traces(self, sequences: Sequence[Sequence_]) -> list[list[str]]:
        lines = []
        for context, events in sequences:
            values = " ".join(str(context.get(f, 0)) for f in self.fields)
            idx = " ".join(str(self.events.index(e)) for e in events)
            lines.append(f"{values} ; {idx}\n")
        done = subprocess.run(
            [str(self.binary)],
            input="".join(lines),
            capture_output=True,
            text=True,
            check=True,
            timeout=60,
        )
        chunks = done.stdout.split("---\n")
        return [c.splitlines() for c in chunks[: len(sequences)]]


def assert_equivalent(device: CppDevice, sequences: Sequence[Sequence_]) -> None:
    """Every sequence gives the same canonical trace in C++ and in the Python runtime."""
    chart = device.chart
    cpp = device.traces(sequences)
    for (context, events), got in zip(sequences, cpp, strict=True):
        full = {f: context.get(f, 0) for f in device.fields}
        expected = python_trace(chart, full, events)
        if got != expected:
            diff = difflib.unified_diff(expected, got, "python", "c++", lineterm="", n=2)
            raise AssertionError(f"{dict(context)} {list(events)}\n" + "\n".join(diff))
