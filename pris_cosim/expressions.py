"""Parameter expressions: ``{Cg/2}``, ``{k12*sqrt(L1*L2)}``.

A small, safe evaluator over Python's AST: numbers (with SPICE suffixes),
names, ``+ - * / **``, parentheses and a few functions. Evaluation works on
floats and on NumPy arrays alike, so one expression evaluates a whole
optimiser population at once. The same tree also prints as C, which is how
the FMU code generator carries ties into the compiled model.
"""

from __future__ import annotations

import ast
import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from .errors import ExpressionError
from .units import SUFFIXES

_FUNCTIONS: dict[str, tuple[Any, str]] = {
    "sqrt": (np.sqrt, "sqrt"),
    "exp": (np.exp, "exp"),
    "log": (np.log, "log"),
    "log10": (np.log10, "log10"),
    "abs": (np.abs, "fabs"),
}
_CONSTANTS = {"pi": np.pi}

_SUFFIXED = re.compile(
    r"(?<![A-Za-z_0-9.])((?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)(meg|mil|[tgkmunpf])[a-z]*",
    re.IGNORECASE,
)

_BINOPS = {
    ast.Add: (lambda a, b: a + b, "+"),
    ast.Sub: (lambda a, b: a - b, "-"),
    ast.Mult: (lambda a, b: a * b, "*"),
    ast.Div: (lambda a, b: a / b, "/"),
    ast.Pow: (lambda a, b: a**b, None),
}


def _body(text: str) -> str:
    return text[1:-1].strip() if text.startswith("{") and text.endswith("}") else text.strip()


def _expand_suffixes(text: str) -> str:
    def repl(m: re.Match[str]) -> str:
        return repr(float(m.group(1)) * SUFFIXES[m.group(2).lower()])

    return _SUFFIXED.sub(repl, text)


class Expression:
    """A parsed arithmetic expression over named parameters.

    Parameters
    ----------
    text : str
        Expression text, with or without surrounding braces. Names are
        case-insensitive and are stored lower-case.
    """

    def __init__(self, text: str):
        self.text = text.strip()
        body = _body(self.text)
        if not body:
            raise ExpressionError(f"empty expression {text!r}")
        try:
            tree = ast.parse(_expand_suffixes(body.strip()).replace("^", "**"), mode="eval")
        except SyntaxError:
            raise ExpressionError(f"cannot parse expression {text!r}") from None
        self._tree = tree.body
        self.names: frozenset[str] = frozenset(self._collect(self._tree))

    def _collect(self, node: ast.AST) -> set[str]:
        if isinstance(node, ast.Constant):
            if not isinstance(node.value, (int, float)) or isinstance(node.value, bool):
                raise ExpressionError(f"only numbers allowed in expression {self.text!r}")
            return set()
        if isinstance(node, ast.Name):
            name = node.id.lower()
            return set() if name in _CONSTANTS else {name}
        if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
            return self._collect(node.left) | self._collect(node.right)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
            return self._collect(node.operand)
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id.lower() in _FUNCTIONS
            and len(node.args) == 1
            and not node.keywords
        ):
            return self._collect(node.args[0])
        raise ExpressionError(f"unsupported construct in expression {self.text!r}")

    def evaluate(self, env: Mapping[str, Any]) -> Any:
        """Evaluate with parameter values from ``env`` (lower-case keys).

        Parameters
        ----------
        env : mapping
            Parameter name (lower-case) to float or array.

        Returns
        -------
        float or numpy.ndarray
        """
        missing = sorted(n for n in self.names if n not in env)
        if missing:
            raise ExpressionError(f"unknown parameter {missing[0]!r} in expression {self.text!r}")
        return self._eval(self._tree, env)

    def _eval(self, node: ast.AST, env: Mapping[str, Any]) -> Any:
        if isinstance(node, ast.Constant):
            return float(node.value)
        if isinstance(node, ast.Name):
            name = node.id.lower()
            return _CONSTANTS[name] if name in _CONSTANTS else env[name]
        if isinstance(node, ast.BinOp):
            return _BINOPS[type(node.op)][0](self._eval(node.left, env), self._eval(node.right, env))
        if isinstance(node, ast.UnaryOp):
            value = self._eval(node.operand, env)
            return -value if isinstance(node.op, ast.USub) else value
        assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
        return _FUNCTIONS[node.func.id.lower()][0](self._eval(node.args[0], env))

    def to_c(self, name_map: Mapping[str, str]) -> str:
        """Render the expression as a C expression.

        Parameters
        ----------
        name_map : mapping
            Parameter name (lower-case) to the C l-value that holds it.
        """
        return self._c(self._tree, name_map)

    def _c(self, node: ast.AST, name_map: Mapping[str, str]) -> str:
        if isinstance(node, ast.Constant):
            return repr(float(node.value))
        if isinstance(node, ast.Name):
            name = node.id.lower()
            return repr(_CONSTANTS[name]) if name in _CONSTANTS else name_map[name]
        if isinstance(node, ast.BinOp):
            left, right = self._c(node.left, name_map), self._c(node.right, name_map)
            symbol = _BINOPS[type(node.op)][1]
            return f"pow({left}, {right})" if symbol is None else f"({left} {symbol} {right})"
        if isinstance(node, ast.UnaryOp):
            operand = self._c(node.operand, name_map)
            return f"(-{operand})" if isinstance(node.op, ast.USub) else operand
        assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
        return f"{_FUNCTIONS[node.func.id.lower()][1]}({self._c(node.args[0], name_map)})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Expression) and _body(self.text) == _body(other.text)

    def __hash__(self) -> int:
        return hash(_body(self.text))

    def __repr__(self) -> str:
        return f"Expression({self.text!r})"
