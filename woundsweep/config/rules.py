"""Exclusion rules: a small, safe expression language over a manifest's columns.

A rule is a Python expression restricted to names (columns), numbers, strings, arithmetic,
comparisons and ``and``/``or``/``not``; it is evaluated column-wise with NumPy, and the rows
where it is true are dropped from the manifest. `compile_rule` also checks its types when the
sweep loads: arithmetic and ordering take numbers, ``==``/``!=`` compare like with like,
``and``/``or``/``not`` take conditions, and the whole rule is a condition.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Collection
from typing import Any

import numpy as np
import pandas as pd

from ..core.errors import SweepError

__all__ = ["STRING_COLUMNS", "compile_rule", "evaluate_rule"]

# The manifest columns that hold names; every other column a rule may name is a number.
STRING_COLUMNS = frozenset({"wound_shape", "skin_type"})
_KIND_NAMES = {"num": "a number", "str": "a string", "bool": "a condition"}

_ALLOWED = (
    ast.Expression, ast.BoolOp, ast.And, ast.Or, ast.UnaryOp, ast.Not, ast.USub, ast.BinOp,
    ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Compare, ast.Lt, ast.LtE, ast.Gt, ast.GtE, ast.Eq,
    ast.NotEq, ast.Name, ast.Load, ast.Constant,
)  # fmt: skip


def compile_rule(path: str, key: str, rule: str, names: Collection[str]) -> ast.Expression:
    """Parse and check ``rule`` (only ``names`` may appear); raise `SweepError` at ``key``."""
    try:
        tree = ast.parse(rule, mode="eval")
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        raise SweepError(path, key, f"cannot parse rule {_short(rule)}") from None
    for node in ast.walk(tree):
        if not isinstance(node, _ALLOWED):
            raise SweepError(
                path, key, f"unsupported syntax {type(node).__name__} in rule {rule!r}"
            )
        if isinstance(node, ast.Name) and node.id not in names:
            raise SweepError(
                path, key, f"unknown name {node.id!r} in rule {rule!r} (expected manifest columns)"
            )
        if isinstance(node, ast.Constant) and not isinstance(node.value, (int, float, str)):
            raise SweepError(path, key, f"unsupported constant {node.value!r} in rule {rule!r}")
        if isinstance(node, ast.Constant) and not isinstance(node.value, str):
            # An int or float (checked above); 10**400 would overflow NumPy, 1e999 is infinity.
            if not _finite(node.value):  # type: ignore[arg-type]
                raise SweepError(path, key, f"number out of range in rule {_short(rule)}")
    try:
        kind = _kind(tree.body)
    except TypeError as err:
        raise SweepError(path, key, f"rule {_short(rule)}: {err}") from None
    except RecursionError:
        raise SweepError(path, key, f"rule {_short(rule)}: nested too deeply") from None
    if kind != "bool":
        raise SweepError(
            path, key, f"rule {_short(rule)} is {_KIND_NAMES[kind]}, expected a condition"
        )
    return tree


def _finite(value: int | float) -> bool:
    try:
        return math.isfinite(float(value)) and abs(value) < 1e300
    except OverflowError:
        return False


def _short(rule: str) -> str:
    return repr(rule if len(rule) <= 80 else rule[:77] + "...")


def _kind(node: ast.AST) -> str:
    """``num``, ``str`` or ``bool``: the type of a checked node; TypeError if they do not fit."""
    if isinstance(node, ast.Constant):
        v = node.value
        return "bool" if isinstance(v, bool) else "str" if isinstance(v, str) else "num"
    if isinstance(node, ast.Name):
        return "str" if node.id in STRING_COLUMNS else "num"
    if isinstance(node, ast.UnaryOp):
        k = _kind(node.operand)
        want = "bool" if isinstance(node.op, ast.Not) else "num"
        if k != want:
            what = "not" if want == "bool" else "unary -"
            raise TypeError(f"{what} takes {_KIND_NAMES[want]}, got {_KIND_NAMES[k]}")
        return want
    if isinstance(node, ast.BinOp):
        kinds = (_kind(node.left), _kind(node.right))
        if kinds != ("num", "num"):
            bad = next(k for k in kinds if k != "num")
            raise TypeError(f"arithmetic takes numbers, got {_KIND_NAMES[bad]}")
        return "num"
    if isinstance(node, ast.BoolOp):
        for value in node.values:
            k = _kind(value)
            if k != "bool":
                raise TypeError(f"and/or take conditions, got {_KIND_NAMES[k]}")
        return "bool"
    if isinstance(node, ast.Compare):
        left = _kind(node.left)
        for op, comp in zip(node.ops, node.comparators):
            right = _kind(comp)
            if left != right:
                raise TypeError(f"compares {_KIND_NAMES[left]} with {_KIND_NAMES[right]}")
            if not isinstance(op, (ast.Eq, ast.NotEq)) and left != "num":
                raise TypeError(f"<, <=, >, >= take numbers, got {_KIND_NAMES[left]}")
            left = right
        return "bool"
    raise TypeError(f"unsupported syntax {type(node).__name__}")


def evaluate_rule(node: ast.AST, df: pd.DataFrame) -> Any:
    """The value of a compiled rule over the columns of ``df`` (a boolean array for a rule)."""
    if isinstance(node, ast.Expression):
        return evaluate_rule(node.body, df)
    if isinstance(node, ast.Constant):
        return node.value
    if isinstance(node, ast.Name):
        return df[node.id].to_numpy()
    if isinstance(node, ast.BoolOp):
        vals = [np.asarray(evaluate_rule(v, df), dtype=bool) for v in node.values]
        op = np.logical_and if isinstance(node.op, ast.And) else np.logical_or
        out: Any = vals[0]
        for v in vals[1:]:
            out = op(out, v)
        return out
    if isinstance(node, ast.UnaryOp):
        v = evaluate_rule(node.operand, df)
        return np.logical_not(v) if isinstance(node.op, ast.Not) else -v
    if isinstance(node, ast.BinOp):
        a, b = evaluate_rule(node.left, df), evaluate_rule(node.right, df)
        # The ufuncs' stub types differ, so mypy joins the dict's values to object.
        return {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide}[  # type: ignore[operator]
            type(node.op)
        ](a, b)
    if isinstance(node, ast.Compare):
        ops: dict[type[ast.cmpop], Any] = {
            ast.Lt: np.less, ast.LtE: np.less_equal, ast.Gt: np.greater, ast.GtE: np.greater_equal,
            ast.Eq: np.equal, ast.NotEq: np.not_equal,
        }  # fmt: skip
        left, out = evaluate_rule(node.left, df), None
        for cmp, comp in zip(node.ops, node.comparators):
            right = evaluate_rule(comp, df)
            res = np.asarray(ops[type(cmp)](left, right), dtype=bool)
            out = res if out is None else np.logical_and(out, res)
            left = right
        return out
    raise AssertionError(f"unreachable: {type(node).__name__}")  # compile_rule rejects the rest
