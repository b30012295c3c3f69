"""``python -m funicular.cli``: the command line."""

import sys

from funicular.cli import main

sys.exit(main())
