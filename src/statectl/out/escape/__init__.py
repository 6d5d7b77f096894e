"""One escaping function per kind of place a name is written into, one module per language.

A name in a device file is the user's: the table loaders accept quotes, backslashes,
newlines, NUL and bidi controls in state, event and device names, and every generator
writes it out. Rule: no generator puts a name (or any text from a model file) into
its output except through the function here for that exact place, so a name can
neither end the place it is in (a docstring's ``\"\"\"``, a ``//`` comment's trailing
``\\``, an XML attribute's quote) nor hide in it (a bidi control reordering the code
around it). Places:

- :mod:`.python`: string literal, comment, docstring text, identifier (testgen);
- :mod:`.cpp`: string literal, comment, identifier (codegen);
- :mod:`.xml`: text and attribute value (SCXML export);
- :mod:`.diagram`: each diagram syntax's label (Mermaid, DOT, PlantUML, Markdown cells;
  SVG is Graphviz's rendering of the DOT text).

Every function returns text that is valid in its place for every input string;
XML 1.0 alone cannot carry some characters at all (NUL and most C0 controls), so
:func:`.xml.attribute` and :func:`.xml.text` refuse those with a
:class:`~statectl.kernel.errors.StatectlError` that names the character.
tests/test_escape.py runs a corpus of hostile names through every generator.
"""

from __future__ import annotations
