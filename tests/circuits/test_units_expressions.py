"""SPICE numbers and parameter expressions."""

import numpy as np
import pytest

from pris_cosim.errors import ExpressionError
from pris_cosim.circuits.expressions import Expression
from pris_cosim.units import format_value, parse_value


@pytest.mark.parametrize(
    "text, value",
    [("10", 10.0), ("10nF", 10e-9), ("4.475k", 4475.0), ("117.3m", 0.1173), ("1meg", 1e6), ("1MEG", 1e6),
     ("2.5e-3", 2.5e-3), ("1u", 1e-6), ("3p", 3e-12), ("5f", 5e-15), ("2g", 2e9), ("1t", 1e12), ("-4.7K", -4700.0),
     (".5", 0.5), ("10ohm", 10.0), ("181uH", 181e-6)],
)
def test_parse_value_suffixes(text, value):
    assert parse_value(text) == pytest.approx(value, rel=1e-15)


@pytest.mark.parametrize("text", ["", "abc", "1..2", "k10", "{x}"])
def test_parse_value_rejects(text):
    with pytest.raises(ValueError):
        parse_value(text)


@pytest.mark.parametrize("x", [1e-9, 0.1173, 4475.0, 1 / 3, 2.53e-12, 123456789.123456789])
def test_format_value_round_trips_exactly(x):
    assert parse_value(format_value(x)) == x


def test_expression_ties_and_population():
    e = Expression("{k12*sqrt(L1*L2)}")
    assert e.names == {"k12", "l1", "l2"}
    assert e.evaluate({"k12": 0.3, "l1": 10.0, "l2": 100.0}) == pytest.approx(0.3 * np.sqrt(1000.0))
    pop = e.evaluate({"k12": np.array([0.1, 0.2]), "l1": 4.0, "l2": 9.0})
    np.testing.assert_allclose(pop, [0.6, 1.2])


def test_expression_suffixes_inside_and_c_output():
    e = Expression("{Cg/2 + 1n}")
    assert e.evaluate({"cg": 2e-9}) == pytest.approx(2e-9)
    assert e.to_c({"cg": "p[3]"}) == "((p[3] / 2.0) + 1e-09)"
    assert Expression("a**2").to_c({"a": "x"}) == "pow(x, 2.0)"


@pytest.mark.parametrize("text", ["{}", "{a +}", "{__import__('os')}", "{a.b}", "{f(a)}", "{'x'}"])
def test_expression_rejects_unsafe_or_malformed(text):
    with pytest.raises(ExpressionError):
        Expression(text)


def test_expression_unknown_name():
    with pytest.raises(ExpressionError, match="'zz'"):
        Expression("{zz*2}").evaluate({})
