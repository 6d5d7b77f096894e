"""The kernel: the chart as a value and the pure step. No I/O, standard library only.

``errors`` (the one error root, diagnostics) and ``codes`` (every diagnostic code),
``model`` (the frozen chart), ``expr`` (the safe expression language) and
``semantics`` (``initial`` and ``step``: the W3C SCXML algorithm, deciding and never
performing). Everything else in statectl imports inward to here.
"""
