"""``python -m statectl``: the same as the ``statectl`` command."""

import sys

from statectl.cli import main

sys.exit(main())
