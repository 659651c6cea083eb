"""The power-law magnetising forms' exponent against a lamination's eddy-current permeability.

A lamination of thickness ``d`` carrying a flux along it has the effective
permeability ``mu tanh(q) / q``, ``q = (1 + j) d / (2 delta)`` (the classical
eddy-current solution; ``q = sqrt(j f / f_e)``). Far above ``f_e`` it falls
as ``(j f)^(-1/2)``: a 45 deg loss angle. A constant-phase magnetising form
``L (j f)^(-b)`` has the loss angle ``b 90 deg``; its bound is checked here
against the closed form, not against the catalogue's own code.
"""

import numpy as np

from estimation.diagnosis.causes.catalogue import MAX_PERMEABILITY_EXPONENT, MagnetisingInductance


def _lamination_permeability(f_over_fe: np.ndarray) -> np.ndarray:
    q = np.sqrt(1j * f_over_fe)
    return np.tanh(q) / q


def test_lamination_loss_angle_approaches_45_degrees_and_never_reaches_the_old_bound():
    x = np.logspace(-4, 6, 20001)
    loss = -np.degrees(np.angle(_lamination_permeability(x)))
    assert abs(loss[-1] - 45.0) < 0.1  # far above the corner
    assert loss.max() < 47.0  # just above 45 deg near the corner (46.6 deg)
    assert MAX_PERMEABILITY_EXPONENT * 90.0 <= loss.max()  # the bound allows what a lamination shows
    assert 0.6 * 90.0 > loss.max() + 5.0  # the exponent allowed before: 54 deg, a loss no lamination has


def test_power_law_forms_keep_to_the_bound():
    for form in ("thesis", "causal"):
        for level in (False, True):
            e = MagnetisingInductance(form=form, group="all", f_ref=10.0, f_max=1e5, level=level)
            b = next(p for p in e.parameters if p.name == "b")
            assert b.upper == MAX_PERMEABILITY_EXPONENT
            assert all(s <= b.upper for s in b.starts)
            # the causal form at the bound: a loss angle of 45 deg, as much reactance as resistance
            if form == "causal":
                z = 2j * np.pi * 1e3 * e.scale(np.array([1e3]), {"b": np.array([b.upper])})[0, 0]
                assert abs(np.degrees(np.angle(z)) - 45.0) < 1e-9
