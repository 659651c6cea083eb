"""Resonance detection and model-order suggestion."""

import numpy as np
import pytest

from estimation.resonances import count_parallel, find_resonances, suggest_sections
from pris_cosim.frf.response import ResponseModel, logspace_hz
from pris_cosim.models.builtin import cascade, get_model


@pytest.mark.parametrize("n", [1, 2, 3, 4, 6])
@pytest.mark.parametrize("noise", [0.0, 0.003])
def test_cascade_sections_recovered(n, noise):
    """An N-section cascade (neutral grounded) has N parallel resonances (thesis 2.1.3)."""
    f = logspace_hz(1e3, 1e8, 3000)
    z = cascade(n, k=0.6).response_set().evaluate(f)["Zin"]
    rng = np.random.default_rng(n)
    z = z * (1 + noise * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)))
    out = suggest_sections({"Zin": (f, z)})
    assert out["sections"] == n
    assert out["counted_on"] == "Zin"


def test_parallel_resonances_at_the_poles():
    """Lightly damped: the |Z| peaks sit at the natural frequencies |Im p|/2 pi of the impedance poles."""
    model = get_model("two-section")
    rm = ResponseModel(model.circuit, "in")
    poles = rm.poles_residues().poles[0]
    natural = np.sort(np.unique(np.round(np.abs(poles.imag[poles.imag > 0]) / (2 * np.pi), 6)))
    f = logspace_hz(10, 1e5, 20000)
    peaks = [r.frequency_hz for r in find_resonances(f, rm.evaluate(f)["Zin"]) if r.kind == "parallel"]
    assert len(peaks) == len(natural) == 2
    np.testing.assert_allclose(peaks, natural, rtol=2e-3)


def test_series_between_parallel():
    f = logspace_hz(1e3, 1e8, 3000)
    rs = find_resonances(f, cascade(3, k=0.6).response_set().evaluate(f)["Zin"])
    kinds = [r.kind for r in rs]
    assert kinds[0] == "parallel" and count_parallel(rs) == 3
    assert all(a != b for a, b in zip(kinds, kinds[1:]))  # alternate parallel / series


def test_even_rounding_and_errors():
    f = logspace_hz(1e3, 1e8, 2000)
    z = cascade(3, k=0.6).response_set().evaluate(f)["Zin"]
    assert suggest_sections({"Zin": (f, z)}, even=True)["sections"] == 4
    with pytest.raises(ValueError, match="none of the impedances"):
        suggest_sections({"Rlvhv": (f, z)})
    with pytest.raises(ValueError, match="same length"):
        find_resonances(f, z[:-1])
