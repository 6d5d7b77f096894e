"""The safe expression language of device tables and of the SCXML ``safe`` datamodel.

A model file from someone else must never run code on the controller, nor stall
it, so guards are a checked, bounded subset of Python expressions. Rules:

1. Allowed: names, literals (numbers, strings, booleans, ``None``, tuples,
   lists, sets, dicts), comparisons (including ``in`` and ``is``), ``and`` /
   ``or`` / ``not``, arithmetic (``+ - * / // %``, unary ``-`` and ``+``),
   conditional expressions, indexing, and attribute reads of public names.
2. Calls are allowed only to the whitelisted functions in :data:`FUNCTIONS`
   and :func:`In`; nothing else is callable, so no method of any object is.
   The whitelist holds *names*: a call ``len(x)`` always reaches the guarded
   ``len``, whatever a variable called ``len`` holds, and an attribute read that
   would yield a method (``'x'.join``) is refused at run time, so data never
   makes a callable reachable.
3. Names starting with ``_`` are refused (``_event`` is the one exception, the
   SCXML system variable), as are attributes that reach frames and code (``f_globals``,
   ``gi_frame``, ``tb_frame``, ``cr_frame``, ``co_*``, ...: :data:`.compiler.INTERNAL_ATTRIBUTES`)
   and lambdas, comprehensions, walrus, ``**``,
   f-strings and starred arguments.
4. The check happens when the model loads and reports every offending node as
   a diagnostic with its column; evaluation then runs the compiled code with no
   builtins at all.
5. Every operation whose cost is not linear in the expression's size is bounded
   (see :data:`LIMITS` and docs/security.md): sequence and string repetition and
   concatenation, ``%``-formatting widths and precisions, integer size,
   ``round`` digits, ``int``/``float`` of text, and the size of every value
   built (:data:`MAX_SIZE` characters or elements, counted through nesting).
   Parts of an expression made of literals only are evaluated at load, so
   ``'a' * 10**10``-like bounds are X304 diagnostics; the rest raise
   :class:`ExpressionRefused` at run time. Expressions longer than
   :data:`MAX_SOURCE` characters or nested deeper than :data:`MAX_DEPTH` are X305.

Two modules: :mod:`.compiler` (rules 1-4, at load) and :mod:`.bounds` (rule 5,
at run time); this one gathers their public names.
"""

from __future__ import annotations

from statectl.kernel.expr.bounds import (
    FUNCTIONS,
    LIMITS,
    MAX_DEPTH,
    MAX_SIZE,
    MAX_SOURCE,
    ExpressionRefused,
    value_size,
)
from statectl.kernel.expr.compiler import (
    CALLABLE_NAMES,
    Expression,
    check_names,
    compile_expression,
    in_target,
)

__all__ = [
    "CALLABLE_NAMES",
    "FUNCTIONS",
    "LIMITS",
    "MAX_DEPTH",
    "MAX_SIZE",
    "MAX_SOURCE",
    "Expression",
    "ExpressionRefused",
    "check_names",
    "compile_expression",
    "in_target",
    "value_size",
]
