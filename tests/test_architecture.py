"""The layout tells the pipeline: imports point toward the kernel, never outward."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import statectl

SRC = Path(statectl.__file__).parent

#: Each layer may import only from the layers listed for it (and from itself).
KERNEL = ("errors", "codes", "exits", "text", "model", "expr", "semantics")
#: ``codes`` (the registry of diagnostic codes), ``exits`` (the exit statuses) and ``text``
#: (the display escape of names) stand beside ``errors``: a layer that may import ``errors``
#: may import them too (see ``allowed_for``).
BESIDE_ERRORS = ("codes", "exits", "text")
ALLOWED: dict[str, tuple[str, ...]] = {
    "errors": (),
    "codes": ("errors",),
    "exits": (),
    "text": (),
    "escape": ("errors",),  # out/escape/: one escaping function per target, per language
    "model": ("errors",),
    "expr": ("errors",),
    "semantics": ("errors", "model", "expr"),
    "observers": ("errors", "model"),
    "tables": ("errors", "model"),
    "build": ("errors", "model", "expr", "observers", "tables", "builder"),
    "builder": ("errors", "model", "expr", "observers", "tables"),  # build's parts
    "recovery": ("errors", "model", "expr", "semantics", "tables"),
    # front/kinds.py: which kind of file a path is (device tables, cell, run config, SCXML)
    "kinds": ("errors", "tables"),
    "guards": (),
    # front/rules/names.py: guards name what their device has (C420, C421); the cell
    # applies it to its devices' guards too
    "names": ("errors", "model", "tables"),
    "rules": (
        "errors",
        "model",
        "expr",
        "semantics",
        "observers",
        "tables",
        "build",
        "recovery",
        "guards",
        "names",
        "profiles",
    ),
    "profiles": ("errors", "model", "tables"),
    "render": ("errors", "model", "observers", "semantics", "escape"),
    "scxml": ("errors", "model", "expr", "semantics", "observers", "runtime", "escape"),
    "runtime": ("errors", "model", "expr", "semantics", "observers"),
    "commands": ("errors",),  # who may command a device: pure, asked at the System's door
    "devices": (
        "errors",
        "model",
        "expr",
        "semantics",
        "observers",
        "runtime",
        "tables",
    ),
    "codegen": ("errors", "model", "expr", "semantics", "observers", "tables", "build", "escape"),
    "cell": ("errors", "model", "expr", "semantics", "observers", "tables", "build", "names"),
    "explore": (
        "errors",
        "model",
        "expr",
        "semantics",
        "observers",
        "tables",
        "build",
        "cell",
        "runtime",
        "devices",
    ),
    "scxml_io": (
        "errors",
        "model",
        "expr",
        "semantics",
        "observers",
        "tables",
        "build",
        "scxml",
        "escape",
    ),
    "journal": (
        "errors",
        "model",
        "expr",
        "semantics",
        "observers",
        "tables",
        "build",
        "recovery",
        "runtime",
        "devices",
    ),
    "system": (
        "errors",
        "commands",
        "model",
        "expr",
        "semantics",
        "observers",
        "tables",
        "build",
        "recovery",
        "runtime",
        "devices",
        "journal",
        "cell",
        "explore",
    ),
    "web": (
        "errors",
        "commands",
        "model",
        "expr",
        "semantics",
        "observers",
        "tables",
        "build",
        "recovery",
        "runtime",
        "devices",
        "render",
        "journal",
        "cell",
        "explore",
    ),
    "distributed": (
        "errors",
        "commands",  # wire.py: a Zenoh post's origin at the System's door
        "model",
        "expr",
        "semantics",
        "observers",
        "tables",
        "build",
        "recovery",
        "runtime",
        "devices",
        "journal",
        "cell",
        "explore",
        "system",
        "web",  # distributed/dashboard.py: the whole cell's page
    ),
    "opcua": (
        "errors",
        "commands",
        "model",
        "expr",
        "semantics",
        "observers",
        "tables",
        "build",
        "recovery",
        "runtime",
        "devices",
        "journal",
        "cell",
        "explore",
        "system",
    ),
    # out/schema.py: JSON Schemas, from the code that reads each file (a run config's
    # sections are read by their owners: runconfig, web, opcua, journal)
    "schema": (
        "errors",
        "model",
        "tables",
        "cell",
        "devices",
        "commands",
        "runconfig",
        "web",
        "opcua",
        "journal",
    ),
    # channels/runconfig.py: a run config, each section parsed by the package that uses it
    "runconfig": ("errors", "tables", "devices", "commands", "journal", "web", "opcua"),
    # api.py: load() and check(), the Python front; it never imports a channel (the CLI)
    "api": ("errors", "model", "build", "kinds", "rules", "scxml"),
    "lsp": (  # channels/lsp: the language server reads what check, verify and run read
        "errors",
        "model",
        "expr",
        "observers",
        "tables",
        "build",
        "rules",
        "recovery",
        "devices",
        "cell",
        "schema",
        "runconfig",  # a run config's problems, as statectl run reports them
    ),
    "testgen": (
        "errors",
        "model",
        "expr",
        "semantics",
        "observers",
        "tables",
        "build",
        "runtime",
        "devices",
        "journal",
        "rules",
        "render",
        "cell",
        "system",
        "explore",
        "escape",
    ),
}
THIRD_PARTY_FREE = (*KERNEL, "observers", "guards")


#: The packages that group the layers in the order data flows (docs/architecture.md):
#: a layer is the module or package one level below its group.
GROUPS = ("kernel", "front", "run", "cell", "channels", "out")
#: Layers that live inside another layer's package (module path -> layer).
NESTED = {
    "front.builder.build": "build",
    "front.rules.guards": "guards",
    "front.rules.names": "names",
    "channels.cli.demo": "demo",
    "out.scxml.tables_io": "scxml_io",
    "run.door": "system",  # the System's one front door, split out of run/system.py
}


def layer_of_module(dotted: str) -> str | None:
    """The layer of ``statectl.<dotted>`` (``kernel.model`` -> ``model``), or None."""
    for prefix, layer in NESTED.items():
        if dotted == prefix or dotted.startswith(prefix + "."):
            return layer
    parts = dotted.split(".")
    if parts[0] == "cell":
        return "explore" if parts[1:2] == ["explore"] else "cell"
    if parts[0] in GROUPS:
        return parts[1] if len(parts) > 1 else None
    return parts[0]


def layer_of(path: Path) -> str:
    rel = path.relative_to(SRC).with_suffix("")
    parts = [p for p in rel.parts if p != "__init__"]
    return layer_of_module(".".join(parts)) or rel.parts[0]


def imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
    return found


def allowed_for(layer: str) -> set[str]:
    """The layers ``layer`` may import: its own, those listed, and codes beside errors."""
    allowed = {*ALLOWED[layer], layer}
    if "errors" in allowed:
        allowed.update(BESIDE_ERRORS)
    return allowed


MODULES = sorted(p for p in SRC.rglob("*.py") if layer_of(p) in ALLOWED)


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(SRC)))
def test_imports_point_inward(path: Path) -> None:
    """A module imports statectl layers only inward of its own (DESIGN.md's rings)."""
    layer = layer_of(path)
    allowed = allowed_for(layer)
    bad = []
    for mod in imported_modules(path):
        parts = mod.split(".")
        if parts[0] != "statectl" or len(parts) == 1:
            continue
        target = layer_of_module(".".join(parts[1:]))
        if target is not None and target not in allowed:
            bad.append(mod)
    assert not bad, f"{path.name} ({layer}) imports outward: {bad}"


@pytest.mark.parametrize(
    "path",
    [p for p in MODULES if layer_of(p) in THIRD_PARTY_FREE],
    ids=lambda p: str(p.relative_to(SRC)),
)
def test_kernel_has_no_third_party_dependencies(path: Path) -> None:
    """errors, model, expr, semantics and observers use the standard library only."""
    import sys

    for mod in imported_modules(path):
        top = mod.split(".")[0]
        assert top in sys.stdlib_module_names or top in {"statectl", "__future__"}, mod


def test_every_layer_is_known() -> None:
    """A new top-level module must be placed in the import rules above, or be the CLI."""
    outer = {"cli", "demo", "runner", "__init__", "__main__", *GROUPS}  # the outer edge
    unknown = {layer_of(p) for p in SRC.rglob("*.py")} - set(ALLOWED) - outer
    assert not unknown, f"add {sorted(unknown)} to ALLOWED in this test"


def test_public_names_exist() -> None:
    """The curated ``__all__`` of the package names only things that exist."""
    for name in statectl.__all__:
        assert hasattr(statectl, name), name


#: Modules are split along their seams before they grow past this (issue 10).
MAX_MODULE_LINES = 600


def test_no_module_is_over_the_line_limit() -> None:
    """Every module under src/ has at most MAX_MODULE_LINES lines."""
    over = {
        str(p.relative_to(SRC)): n
        for p in sorted(SRC.rglob("*.py"))
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES
    }
    assert over == {}, f"split these along their seams: {over}"


#: A function longer than this is split into helpers, each one job (issue 26).
MAX_FUNCTION_LINES = 80
#: Functions still over the limit, by ``module path:qualified name``. The set may only
#: shrink: the test fails when a listed function is now short, so remove it here.
LONG_FUNCTIONS_TO_SPLIT: frozenset[str] = frozenset()


def function_lengths(path: Path) -> dict[str, int]:
    """Lines of every function and method in ``path``, by qualified name (``A.f``)."""
    lengths: dict[str, int] = {}

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                name = f"{prefix}{child.name}"
                if not isinstance(child, ast.ClassDef):
                    end = child.end_lineno or child.lineno
                    lengths.setdefault(name, 0)
                    lengths[name] = max(lengths[name], end - child.lineno + 1)
                visit(child, f"{name}.")
            else:
                visit(child, prefix)

    visit(ast.parse(path.read_text(encoding="utf-8")), "")
    return lengths


def test_no_function_is_over_the_line_limit() -> None:
    """No function or method under src/ is over MAX_FUNCTION_LINES, but the listed few."""
    long = {
        f"{p.relative_to(SRC).as_posix()}:{name}"
        for p in sorted(SRC.rglob("*.py"))
        for name, n in function_lengths(p).items()
        if n > MAX_FUNCTION_LINES
    }
    assert long - LONG_FUNCTIONS_TO_SPLIT == set(), "split these into helpers, each one job"
    assert LONG_FUNCTIONS_TO_SPLIT - long == set(), "now short: drop them from the list above"


#: Modules whose ``__all__`` still names what another module defines, with why. A module
#: that only passes names on is a second address for them: importers drift between the
#: two and nobody can tell which one owns the name (issue 26).
PASSES_NAMES_ON: dict[str, str] = {
    "front/builder/build.py": "step 2's one door: the 'build' layer every later stage imports",
    "cell/model.py": "the cell's values, re-exported for cell/explore (its importers move later)",
    "cell/explore/search.py": "Progress, for cell/explore's own modules",
}


def defined_names(tree: ast.Module) -> set[str]:
    """The names a module binds at its top level itself (not by importing them)."""
    names: set[str] = set()
    for node in tree.body:
        for sub in ast.walk(node) if isinstance(node, ast.If | ast.Try) else [node]:
            if isinstance(sub, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                names.add(sub.name)
            elif isinstance(sub, ast.Assign | ast.AnnAssign):
                targets = sub.targets if isinstance(sub, ast.Assign) else [sub.target]
                names |= {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
    return names


def passed_on(path: Path) -> list[str]:
    """Names in ``path``'s ``__all__`` that it imports instead of defining."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    listed: list[str] = []
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            listed = [e.value for e in ast.walk(node.value) if isinstance(e, ast.Constant)]
    return sorted(set(listed) - defined_names(tree))


def test_modules_export_only_what_they_define() -> None:
    """A module's ``__all__`` lists its own names; a package's ``__init__`` gathers its API."""
    found = {
        rel: names
        for p in sorted(SRC.rglob("*.py"))
        if p.name != "__init__.py"
        and (rel := p.relative_to(SRC).as_posix()) not in PASSES_NAMES_ON
        and (names := passed_on(p))
    }
    assert found == {}, "import these from the module that defines them"
    still = {rel for rel in PASSES_NAMES_ON if passed_on(SRC / rel)}
    assert still == set(PASSES_NAMES_ON), "no longer passes names on: drop it from the list"
