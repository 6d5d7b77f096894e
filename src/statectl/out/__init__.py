"""What statectl writes from a chart: diagrams, C++, test suites and SCXML.

``render`` (Mermaid, DOT, PlantUML, SVG, Markdown), ``codegen`` (C++17),
``testgen`` (pytest suites and coverage), ``scxml`` (SCXML read, written and run;
``scxml.tables_io`` converts between SCXML and device tables).
"""
