"""``python -m woundsweep`` is the same as the ``woundsweep`` console script."""

from .cli import console_main

console_main()
