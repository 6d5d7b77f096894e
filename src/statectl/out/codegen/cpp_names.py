"""C++ identifiers for chart names: valid, unique and never a keyword
(:func:`identifiers`). Its own module: the writer and the flattener both name things.
"""

from __future__ import annotations

from collections.abc import Iterable

from statectl.out.escape.cpp import identifier_words

#: Longest identifier made from a name (before a number that makes it distinct): the
#: namespace names the header file, and a 1 MB name must not become a 1 MB file name.
IDENT_LIMIT = 64

# -- identifiers -------------------------------------------------------------------------------

_CPP_KEYWORDS = frozenset(
    (
        "alignas",
        "alignof",
        "and",
        "and_eq",
        "asm",
        "auto",
        "bitand",
        "bitor",
        "bool",
        "break",
        "case",
        "catch",
        "char",
        "char16_t",
        "char32_t",
        "class",
        "compl",
        "const",
        "constexpr",
        "const_cast",
        "continue",
        "decltype",
        "default",
        "delete",
        "do",
        "double",
        "dynamic_cast",
        "else",
        "enum",
        "explicit",
        "export",
        "extern",
        "false",
        "float",
        "for",
        "friend",
        "goto",
        "if",
        "inline",
        "int",
        "long",
        "mutable",
        "namespace",
        "new",
        "noexcept",
        "not",
        "not_eq",
        "nullptr",
        "operator",
        "or",
        "or_eq",
        "private",
        "protected",
        "public",
        "register",
        "reinterpret_cast",
        "return",
        "short",
        "signed",
        "sizeof",
        "static",
        "static_assert",
        "static_cast",
        "struct",
        "switch",
        "template",
        "this",
        "thread_local",
        "throw",
        "true",
        "try",
        "typedef",
        "typeid",
        "typename",
        "union",
        "unsigned",
        "using",
        "virtual",
        "void",
        "volatile",
        "wchar_t",
        "while",
        "xor",
        "xor_eq",
    )
)


def identifiers(names: Iterable[str], *, lower: bool = False) -> dict[str, str]:
    """A distinct C++ identifier per name: ``Movement completion`` -> ``MovementCompletion``."""
    out: dict[str, str] = {}
    used: set[str] = set()
    for name in names:
        words = identifier_words(name)
        if lower:
            base = "_".join(w.lower() for w in words)[:IDENT_LIMIT].rstrip("_") or "x"
        else:
            base = "".join(w[:1].upper() + w[1:] for w in words)[:IDENT_LIMIT] or "X"
        if base[0].isdigit() or base in _CPP_KEYWORDS or base.startswith("_"):
            base = ("s_" if lower else "S") + base
        ident, n = base, 2
        while ident in used:
            ident, n = f"{base}{n}", n + 1
        used.add(ident)
        out[name] = ident
    return out
