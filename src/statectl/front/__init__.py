"""The paper's steps 1-3: tables in, a checked chart and its observers out.

``tables`` reads the State, Event and Recovery tables (YAML, CSV, XLSX, Markdown);
``builder`` builds the chart from them (``builder.build`` loads and builds a file);
``rules`` is ``statectl check`` (with ``rules.guards``, the guard prover);
``observers`` derives the Subject, observers and invoke numbers; ``recovery`` judges
the Recovery table against the chart; ``profiles`` are the shipped standard devices.
"""
