"""Cells: several devices, their links, and the verification of the whole.

``model`` (the cell value: devices, links, environment, invariants, recovery goals),
``reader`` (cell files), ``nodes`` and ``options`` (a cell spread over processes),
``expressions`` and ``values`` (global expressions), and ``explore`` (``statectl
verify``: the composed state space, counterexamples, Promela export).
"""
