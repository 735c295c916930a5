"""``python -m woundsweep`` is the same as the ``woundsweep`` console script."""

import sys

from .cli import main

sys.exit(main())
