"""MkDocs hooks: the reference pages the code holds, generated at build time (mkdocs.yml).

Rules:
1. What the code holds is not copied into the docs: the diagnostic codes come from
   the registry (``statectl.kernel.codes.REGISTRY``), the commands from the argparse
   parser (``statectl.channels.cli.build_parser``), the Python API's list of names from
   ``statectl.__all__`` (each rendered from its docstring by mkdocstrings). Each is a page
   made here, so a new code, option or name appears without editing a page.
2. A link from a page to a file of the repository outside ``docs/`` (``bench/README.md``,
   a source file) is a file, not a page of the site: it is shown as its path, so
   ``mkdocs build --strict`` can refuse every link that is broken.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path
from typing import Any

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parents[1]

#: The generated pages (rule 1): path in the site -> the function that writes it.
CODES, CLI, API = "reference/codes.md", "reference/cli.md", "reference/python.md"


def on_files(files: Files, config: Any) -> Files:
    """Rule 1: add the generated pages to the site."""
    for path, make in ((CODES, codes_page), (CLI, cli_page), (API, api_page)):
        files.append(File.generated(config, path, content=make()))
    return files


def codes_page() -> str:
    """Every registered diagnostic code: severity, summary, the section that explains it."""
    from statectl.kernel.codes import ALL

    lines = [
        "# Diagnostic codes",
        "",
        "Every code statectl reports, from its registry (`statectl.kernel.codes`); "
        "`statectl check --explain CODE` prints the same on the command line. The link "
        "goes to the section that explains the code and how to fix it.",
        "",
        "| code | severity | what it means | explained in |",
        "|---|---|---|---|",
    ]
    for c in ALL:
        also = "".join(f" (or {s.value})" for s in c.also)
        page = c.page.removeprefix("docs/")
        where = f"[{page.removesuffix('.md')}](../{page}#{c.anchor})"
        summary = _cell(c.summary)
        lines.append(f"| <a id='{c.code.lower()}'></a>`{c.code}` | {c.severity.value}{also} "
                     f"| {summary} | {where} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def cli_page() -> str:
    """Every command and subcommand with its options, from the parser itself."""
    from statectl.channels.cli import build_parser

    parser = build_parser()
    lines = [
        "# Command line",
        "",
        "Every `statectl` command and its options, from the command's own parser "
        "(`statectl COMMAND --help` prints the same). Exit codes: 0 success, 1 problems "
        "found, 2 usage error (also an input file that does not exist, and an optional "
        "extra that is not installed: the message names it). Every `--out` follows "
        "[one rule](../outputs.md).",
        "",
    ]
    for name, summary, sub in _subcommands(parser, "statectl"):
        lines += [f"## `{name}`", "", *_usage(sub, summary), ""]
    return "\n".join(lines)


def _subcommands(
    parser: argparse.ArgumentParser, prefix: str
) -> list[tuple[str, str, argparse.ArgumentParser]]:
    """``(statectl journal show, its help line, parser)`` for every leaf command."""
    found: list[tuple[str, str, argparse.ArgumentParser]] = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help or "" for a in action._choices_actions}
            for name, sub in action.choices.items():
                here = f"{prefix} {name}"
                found += _subcommands(sub, here) or [(here, helps.get(name, ""), sub)]
    return found


def _usage(parser: argparse.ArgumentParser, summary: str) -> list[str]:
    """The command's description (else its help line), usage line and its arguments."""
    about = parser.description or (summary[:1].upper() + summary[1:] + "." if summary else "")
    lines = [about, "", "```text", parser.format_usage().strip(), "```", ""]
    rows = ["| argument | what it does |", "|---|---|"]
    for a in parser._actions:
        if isinstance(a, argparse._HelpAction) or a.help == argparse.SUPPRESS:
            continue
        flag = ", ".join(a.option_strings) or (a.metavar or a.dest)
        if a.choices and not isinstance(a, argparse._SubParsersAction):
            flag += " {" + ",".join(map(str, a.choices)) + "}"
        default = a.default not in (None, False, argparse.SUPPRESS) and a.option_strings
        positional = "optional" if a.nargs in ("?", "*") else "required"
        text = (a.help or ("" if a.option_strings else positional)) + (
            f" (default: {a.default})" if default else ""
        )
        rows.append(f"| `{_cell(flag)}` | {_cell(text)} |")
    return [*lines, *rows] if len(rows) > 2 else lines


def _cell(text: str) -> str:
    """``text`` in a Markdown table cell: its ``|`` escaped."""
    return text.replace("|", "\\|")


def api_page() -> str:
    """The stable Python API: every name of ``statectl.__all__``, from its docstring."""
    import statectl

    lines = [
        "# Python API reference",
        "",
        "Every name `import statectl` exports (`statectl.__all__`), documented from its "
        "docstring. [The Python API](../api.md) shows them at work.",
        "",
    ]
    for name in sorted(statectl.__all__):
        if name.startswith("_"):
            continue
        where = statectl._LAZY.get(name) or getattr(statectl, name).__module__
        lines += [f"::: {where}.{name}", ""]
    return "\n".join(lines)


#: ``[text](../path)`` whose path leaves docs/ (rule 2).
_OUTSIDE = re.compile(r"\[([^\]]+)\]\((\.\./[^)#\s]+)(#[^)\s]*)?\)")


def on_page_markdown(markdown: str, page: Any, config: Any, files: Files) -> str:
    """Rule 2: a link to a repository file outside docs/ becomes its path."""
    here = (Path(config["docs_dir"]) / page.file.src_path).parent

    def name(m: re.Match[str]) -> str:
        target = (here / m.group(2)).resolve()
        try:
            inside = target.relative_to(Path(config["docs_dir"]).resolve())
        except ValueError:
            inside = None
        if inside is not None:
            return m.group(0)
        path = target.relative_to(ROOT).as_posix()
        text = m.group(1)
        return text if text.strip("`") == path else f"{text} (`{path}` in the repository)"

    return _OUTSIDE.sub(name, markdown)
