"""Click parameter types shared by the commands: finite numbers only."""

from __future__ import annotations

import math
from typing import Any

import click

__all__ = ["FiniteFloat"]


class FiniteFloat(click.ParamType):
    """A float that is finite (no ``nan``, ``inf``) and, if given, within ``[min, max]``."""

    name = "float"

    def __init__(self, min: float | None = None, max: float | None = None) -> None:  # noqa: A002
        self.min, self.max = min, max

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        if isinstance(value, float) and math.isfinite(value):
            number = value
        else:
            try:
                number = float(value)
            except (TypeError, ValueError):
                self.fail(f"{value!r} is not a number", param, ctx)
            if not math.isfinite(number):
                self.fail(f"{value!r} is not a finite number", param, ctx)
        if self.min is not None and number < self.min:
            self.fail(f"{value!r} is below the minimum {self.min:g}", param, ctx)
        if self.max is not None and number > self.max:
            self.fail(f"{value!r} is above the maximum {self.max:g}", param, ctx)
        return number

    def __repr__(self) -> str:
        return f"FiniteFloat({self.min!r}, {self.max!r})"
