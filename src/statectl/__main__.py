"""``python -m statectl``: the same as the ``statectl`` command."""

import sys

from statectl.channels.cli import main

sys.exit(main())
