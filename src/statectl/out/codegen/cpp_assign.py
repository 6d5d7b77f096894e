"""The C++ text of the assignment groups (:mod:`statectl.out.codegen.assign`): one function
per group, computing every new value over the context first and storing them after, and
the ``kAssigns`` table the ASSIGN effects index."""

from __future__ import annotations

from statectl.out.codegen.flat import FlatChart
from statectl.out.escape.cpp import comment as _comment

__all__ = ["assign_functions"]


def assign_functions(flat: FlatChart) -> list[str]:
    """Lines of the ``detail`` namespace: ``assign_N(Context&)`` and ``kAssigns``."""
    out = ["// Data assignments of the event rows (assign): values first, then the stores."]
    for g in flat.assignments:
        out.append(f"// assign {g.index}: {_comment(g.source)}")
        out.append(f"inline void assign_{g.index}(Context& c) noexcept {{")
        for k, (_, expr) in enumerate(g.stores):
            out.append(f"  const V v{k} = {expr};")
        for k, (field, _) in enumerate(g.stores):
            if field:
                out.append(f"  c.{field} = v{k};")
            else:
                out.append(f"  static_cast<void>(v{k});")
        out.append("  static_cast<void>(c);")
        out.append("}")
    out.append("")
    out.append("using AssignFn = void (*)(Context&) noexcept;")
    if flat.assignments:
        out.append(f"inline constexpr AssignFn kAssigns[{len(flat.assignments)}] = {{")
        out.extend(f"    &assign_{g.index}," for g in flat.assignments)
        out.append("};")
    else:
        out.append("inline constexpr AssignFn kAssigns[1] = {nullptr};  // unused: no assign")
    out.append("")
    return out
