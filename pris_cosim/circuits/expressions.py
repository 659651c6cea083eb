"""Parameter expressions: ``{Cg/2}``, ``{k12*sqrt(L1*L2)}``.

A small, safe evaluator over Python's AST: numbers (with SPICE suffixes),
names, ``+ - * / **``, parentheses and a few functions. Evaluation works on
floats and on NumPy arrays alike, so one expression evaluates a whole
optimiser population at once. The same tree also prints as C, which is how
the FMU code generator carries ties into the compiled model.

Evaluation of plain numbers is strict: a division by zero, an overflow, a
function outside its domain (``sqrt(-1)``, ``log(0)``) or a negative base
to a fractional power raises :class:`~pris_cosim.errors.ExpressionError`
with one line. Arrays (optimiser populations) are evaluated quietly: their
non-finite members are left to the caller's value checks. Expressions
longer than :data:`MAX_LENGTH` characters or nested deeper than
:data:`MAX_DEPTH` levels are refused.
"""

from __future__ import annotations

import ast
import math
import operator
import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from pris_cosim.errors import ExpressionError
from pris_cosim.units import SUFFIXES

#: Longest accepted expression text, characters.
MAX_LENGTH = 4000
#: Deepest accepted nesting of operations (a chain of n sums counts n levels).
MAX_DEPTH = 200

_FUNCTIONS: dict[str, tuple[Any, str]] = {
    "sqrt": (np.sqrt, "sqrt"),
    "exp": (np.exp, "exp"),
    "log": (np.log, "log"),
    "log10": (np.log10, "log10"),
    "abs": (np.abs, "fabs"),
}
_SCALAR_FUNCTIONS: dict[str, Any] = {"sqrt": math.sqrt, "exp": math.exp, "log": math.log, "log10": math.log10,
                                     "abs": abs}
_CONSTANTS = {"pi": np.pi}

_SUFFIXED = re.compile(
    r"(?<![A-Za-z_0-9.])((?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)(meg|mil|[tgkmunpf])[a-z]*(?![A-Za-z0-9_.])",
    re.IGNORECASE,
)
# A number starts where no name or number continues; it must then be a plain decimal literal.
_NUMBER_START = re.compile(r"(?<![A-Za-z_0-9.])(?=[0-9]|\.[0-9])")
_DECIMAL = re.compile(r"(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?(?![A-Za-z0-9_.])")

_BINOPS = {
    ast.Add: (operator.add, "+"),
    ast.Sub: (operator.sub, "-"),
    ast.Mult: (operator.mul, "*"),
    ast.Div: (operator.truediv, "/"),
    ast.Pow: (operator.pow, None),
}
_OP_WORDS = {ast.Add: "sum", ast.Sub: "difference", ast.Mult: "product", ast.Div: "quotient", ast.Pow: "power"}


def _quote(text: str, limit: int = 60) -> str:
    """Expression text for a one-line message (whitespace collapsed, long text shortened)."""
    s = " ".join(str(text).split())
    return repr(s if len(s) <= limit else s[: limit - 3] + "...")


def _depth(tree: ast.AST) -> int:
    """Nesting depth of an AST, computed without recursion."""
    deepest, stack = 0, [(tree, 1)]
    while stack:
        node, level = stack.pop()
        deepest = max(deepest, level)
        stack.extend((child, level + 1) for child in ast.iter_child_nodes(node))
    return deepest


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
        if len(self.text) > MAX_LENGTH:
            raise ExpressionError(f"expression of {len(self.text)} characters is longer than the limit of {MAX_LENGTH}")
        body = _body(self.text)
        if not body:
            raise ExpressionError(f"empty expression {_quote(text)}")
        if "{" in body or "}" in body:
            raise ExpressionError(f"unbalanced braces in expression {_quote(text)}")
        source = _expand_suffixes(body.strip()).replace("^", "**")
        for m in _NUMBER_START.finditer(source):
            if not _DECIMAL.match(source, m.start()):
                bad = re.match(r"[0-9A-Za-z_.]+", source[m.start():])
                raise ExpressionError(f"malformed number {bad.group(0) if bad else source[m.start():][:20]!r} "
                                      f"in expression {_quote(text)} (decimal numbers with SPICE suffixes only)")
        depth = 0
        for ch in source:  # bound the parser's recursion before it runs
            depth = depth + 1 if ch == "(" else depth - 1 if ch == ")" else depth
            if depth > MAX_DEPTH:
                raise ExpressionError(f"expression {_quote(text)} is nested deeper than {MAX_DEPTH} levels")
        try:
            tree = ast.parse(source, mode="eval")
        except (SyntaxError, ValueError):
            raise ExpressionError(f"cannot parse expression {_quote(text)}") from None
        except (RecursionError, MemoryError):
            raise ExpressionError(f"expression {_quote(text)} is too deeply nested") from None
        self._tree = tree.body
        if _depth(self._tree) > MAX_DEPTH:
            raise ExpressionError(f"expression {_quote(text)} has more than {MAX_DEPTH} levels of operations")
        self.names: frozenset[str] = frozenset(self._collect(self._tree))

    def _collect(self, node: ast.AST) -> set[str]:
        if isinstance(node, ast.Constant):
            if not isinstance(node.value, (int, float)) or isinstance(node.value, bool):
                raise ExpressionError(f"only numbers allowed in expression {_quote(self.text)}")
            try:
                finite = math.isfinite(float(node.value))
            except OverflowError:
                finite = False
            if not finite:
                raise ExpressionError(f"number outside the range of double-precision numbers in expression "
                                      f"{_quote(self.text)}")
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
        raise ExpressionError(f"unsupported construct in expression {_quote(self.text)}")

    def evaluate(self, env: Mapping[str, Any]) -> Any:
        """Evaluate with parameter values from ``env`` (lower-case keys).

        Parameters
        ----------
        env : mapping
            Parameter name (lower-case) to float or array.

        Returns
        -------
        float or numpy.ndarray

        Raises
        ------
        ExpressionError
            Unknown name; for plain numbers also a division by zero, an
            overflow or a function outside its domain (one line).
        """
        missing = sorted(n for n in self.names if n not in env)
        if missing:
            raise ExpressionError(f"unknown parameter {missing[0]!r} in expression {_quote(self.text)}")
        scalar = all(np.ndim(env[n]) == 0 for n in self.names)
        if scalar:
            return self._scalar(self._tree, {n: float(env[n]) for n in self.names})
        with np.errstate(all="ignore"):
            return self._eval(self._tree, env)

    def _eval(self, node: ast.AST, env: Mapping[str, Any]) -> Any:
        if isinstance(node, ast.Constant):
            return float(node.value)
        if isinstance(node, ast.Name):
            name = node.id.lower()
            return _CONSTANTS[name] if name in _CONSTANTS else env[name]
        if isinstance(node, ast.BinOp):
            left, right = self._eval(node.left, env), self._eval(node.right, env)
            if isinstance(node.op, ast.Pow):
                return np.power(np.asarray(left, float), right)
            return _BINOPS[type(node.op)][0](left, right)
        if isinstance(node, ast.UnaryOp):
            value = self._eval(node.operand, env)
            return -value if isinstance(node.op, ast.USub) else value
        assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
        return _FUNCTIONS[node.func.id.lower()][0](self._eval(node.args[0], env))

    def _scalar(self, node: ast.AST, env: Mapping[str, float]) -> float:
        """Strict evaluation on Python floats: every failure is an ExpressionError."""
        if isinstance(node, ast.Constant):
            return float(node.value)
        if isinstance(node, ast.Name):
            name = node.id.lower()
            value = _CONSTANTS[name] if name in _CONSTANTS else env[name]
            if not math.isfinite(value):
                raise ExpressionError(f"parameter {name!r} is not finite ({value!r}) in expression {_quote(self.text)}")
            return float(value)
        if isinstance(node, ast.UnaryOp):
            value = self._scalar(node.operand, env)
            return -value if isinstance(node.op, ast.USub) else value
        if isinstance(node, ast.BinOp):
            left, right = self._scalar(node.left, env), self._scalar(node.right, env)
            word = _OP_WORDS[type(node.op)]
            if isinstance(node.op, ast.Div) and right == 0.0:
                raise ExpressionError(f"division by zero in expression {_quote(self.text)}")
            if isinstance(node.op, ast.Pow):
                if left == 0.0 and right < 0.0:
                    raise ExpressionError(f"zero to a negative power in expression {_quote(self.text)}")
                if left < 0.0 and right != int(right):
                    raise ExpressionError(f"negative number to a fractional power in expression {_quote(self.text)}")
            try:
                result = _BINOPS[type(node.op)][0](left, right)
            except (OverflowError, ZeroDivisionError):
                result = math.inf
            if isinstance(result, complex) or not math.isfinite(result):
                raise ExpressionError(f"the {word} overflows in expression {_quote(self.text)}")
            return float(result)
        assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
        name = node.func.id.lower()
        arg = self._scalar(node.args[0], env)
        try:
            result = _SCALAR_FUNCTIONS[name](arg)
        except OverflowError:
            raise ExpressionError(f"{name}({arg:.6g}) overflows in expression {_quote(self.text)}") from None
        except ValueError:
            raise ExpressionError(f"{name}({arg:.6g}) is undefined in expression {_quote(self.text)}") from None
        return float(result)

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
