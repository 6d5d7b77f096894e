"""The parts of step 2 (:mod:`statectl.front.builder.build`): state rows, event rows, the chart, and
the inverse. Import the public names from :mod:`statectl.front.builder.build`; this package is where
they are implemented, split along the rules they check. (Not named ``build/``: that name
is ignored by git and skipped by ruff as a build output directory.)
"""
