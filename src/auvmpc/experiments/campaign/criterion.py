"""The success criterion: a small, safe expression language over result columns.

Part of :mod:`auvmpc.experiments.campaign` (docs/campaigns.md).
"""

from __future__ import annotations

import ast
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from auvmpc.errors import ConfigError

if TYPE_CHECKING:
    import pandas as pd


WILSON_Z_95 = 1.959963984540054  # two-sided 95 % normal quantile


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


_COMPARISONS: dict[type, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    ast.Lt: np.less,
    ast.LtE: np.less_equal,
    ast.Gt: np.greater,
    ast.GtE: np.greater_equal,
    ast.Eq: np.equal,
    ast.NotEq: np.not_equal,
}


@dataclass(frozen=True)
class Criterion:
    """A parsed success criterion.

    Grammar: comparisons ``name OP number`` (``<  <=  >  >=  ==  !=``, chains like
    ``0 <= x < 1`` allowed) combined with ``and``, ``or``, ``not`` and parentheses. A name is
    a metric or parameter column; one that is not a Python identifier is written in
    backticks (`` `plant.scale.Iz_rb` ``). A comparison involving a missing value (null
    metric) is false. Parsed with :mod:`ast` and evaluated by walking the tree: nothing is
    ever passed to ``eval``.
    """

    text: str
    tree: ast.Expression
    names: tuple[str, ...]
    aliases: dict[str, str] = field(default_factory=dict)

    def evaluate(self, frame: pd.DataFrame) -> np.ndarray:
        """Boolean array, one per row; rows with status other than ``ok`` are False."""
        missing = [name for name in self.names if name not in frame.columns]
        if missing:
            known = [c for c in frame.columns if c not in ("index", "seed", "status", "error")]
            raise ConfigError("criterion", missing[0], f"unknown column; known: {known}")
        values = {}
        for name in self.names:
            try:
                values[name] = frame[name].astype(float).to_numpy()
            except (TypeError, ValueError):
                raise ConfigError("criterion", name, "not a numeric column") from None
        result = self._node(self.tree.body, values, len(frame))
        return np.asarray(result & (frame["status"] == "ok").to_numpy(), dtype=bool)

    def _node(self, node: ast.AST, values: dict[str, np.ndarray], n: int) -> Any:
        if isinstance(node, ast.BoolOp):
            parts = [self._node(v, values, n) for v in node.values]
            combine = np.logical_and if isinstance(node.op, ast.And) else np.logical_or
            return functools.reduce(combine, parts)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
            return np.logical_not(self._node(node.operand, values, n))
        if isinstance(node, ast.Compare):
            left = self._operand(node.left, values, n)
            result = np.ones(n, dtype=bool)
            for op, right_node in zip(node.ops, node.comparators, strict=True):
                right = self._operand(right_node, values, n)
                known = ~np.isnan(left) & ~np.isnan(right)
                with np.errstate(invalid="ignore"):
                    result &= known & _COMPARISONS[type(op)](left, right)
                left = right
            return result
        raise AssertionError(f"unchecked node {ast.dump(node)}")  # parse_criterion rejects it

    def _operand(self, node: ast.AST, values: dict[str, np.ndarray], n: int) -> np.ndarray:
        if isinstance(node, ast.Name):
            return values[self.aliases.get(node.id, node.id)]
        return np.full(n, _number(node))


def _number(node: ast.AST) -> float:
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        value = _number(node.operand)
        return -value if isinstance(node.op, ast.USub) else value
    if isinstance(node, ast.Constant) and _is_number(node.value):
        return float(node.value)
    raise ValueError


def parse_criterion(text: str) -> Criterion:
    """Parse a success criterion (grammar in :class:`Criterion`).

    Raises
    ------
    ConfigError
        Naming ``criterion`` and the offending part.
    """
    aliases: dict[str, str] = {}
    parts = text.split("`")
    if len(parts) % 2 == 0:
        raise ConfigError("criterion", text, "unbalanced backtick")
    for i in range(1, len(parts), 2):
        alias = f"_column_{i // 2}"
        aliases[alias] = parts[i]
        parts[i] = alias
    try:
        tree = ast.parse("".join(parts).strip(), mode="eval")
    except SyntaxError:
        raise ConfigError("criterion", text, "not a valid expression") from None
    names: list[str] = []

    def check(node: ast.AST, boolean: bool) -> None:
        if boolean and isinstance(node, ast.BoolOp):
            for value in node.values:
                check(value, True)
        elif boolean and isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
            check(node.operand, True)
        elif boolean and isinstance(node, ast.Compare):
            if not all(type(op) in _COMPARISONS for op in node.ops):
                raise ConfigError("criterion", text, "comparisons are < <= > >= == !=")
            for operand in (node.left, *node.comparators):
                check(operand, False)
        elif not boolean and isinstance(node, ast.Name):
            name = aliases.get(node.id, node.id)
            if name not in names:
                names.append(name)
        elif not boolean:
            try:
                _number(node)
            except ValueError:
                raise ConfigError(
                    "criterion", ast.unparse(node), "operands are column names and numbers"
                ) from None
        else:
            raise ConfigError(
                "criterion", ast.unparse(node), "expected comparisons joined by and / or / not"
            )

    check(tree.body, True)
    return Criterion(text, tree, tuple(names), aliases)


def wilson_interval(successes: int, trials: int, z: float = WILSON_Z_95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % by default); (0, 1) if no trials."""
    if trials == 0:
        return 0.0, 1.0
    p = successes / trials
    denominator = 1 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denominator
    half = z / denominator * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials))
    return max(0.0, centre - half), min(1.0, centre + half)
