"""Never a silently wrong number: extreme element values against a 60-digit nodal solve (mpmath).

Every case either matches the high-precision reference to 1e-6 relative (the
real and the imaginary part of Zin separately, where they matter) or is
refused with exit 2 and one line naming the element.
"""

from __future__ import annotations

import json
import subprocess
import sys

import mpmath as mp
import pytest

from pris_cosim.circuits.conditioning import check_response_set
from pris_cosim.errors import CircuitError
from pris_cosim.models.builtin import get_model

FREQS = [10.0, 1e3, 1e5, 1e6]

CASES = {
    # name: (netlist, port, refused element or None)
    "tiny_R_series": ("R1 n1 n2 1e-9\nL1 n2 0 1e-3\nC1 n1 0 1e-9\n", "n1", "R1"),
    "tiny_R_with_huge_shunt": ("R1 n1 n2 1e-9\nL1 n2 0 1e-3\nC1 n1 0 1e-9\nR2 n1 0 1e15\n", "n1", "R1"),
    "moderate_R_series": ("R1 n1 n2 1e-3\nL1 n2 0 1e-3\nC1 n1 0 1e-9\n", "n1", None),
    "tiny_and_huge_C": ("R1 n1 n2 10\nL1 n2 0 1e-3\nC1 n1 0 1e-18\nC2 n2 0 1e3\n", "n1", None),
    "inductances_21_decades": ("R1 n1 n2 1e-9\nL1 n2 0 1e-15\nL2 n1 n3 1e6\nR3 n3 0 1e15\nC1 n1 0 1e-18\n",
                               "n1", None),
    "coupling_near_one": ("R1 n1 n2 1\nL1 n2 0 1\nL2 n3 0 1\nR2 n3 0 1\nK1 L1 L2 0.999999999\nC1 n1 0 1e-9\n",
                          "n1", None),
}


def reference_zin(text: str, port: str, f: float) -> complex:
    """Zin from the modified-nodal equations solved with 60 significant digits."""
    mp.mp.dps = 60
    el = [ln.split() for ln in text.strip().splitlines()]
    nodes = sorted({x for e in el if e[0][0] in "RLC" for x in e[1:3]} - {"0"})
    idx = {n: i for i, n in enumerate(nodes)}
    inds = [e for e in el if e[0][0] == "L"]
    pos = {e[0]: i for i, e in enumerate(inds)}
    N, m = len(nodes), len(inds)
    s = 2j * mp.pi * mp.mpf(f)
    K = mp.matrix(N + m, N + m)
    for e in el:
        kind, a, b, v = e[0][0], e[1], e[2], mp.mpf(e[3])
        if kind in "RC":
            y = 1 / v if kind == "R" else s * v
            for p, sp in ((a, 1), (b, -1)):
                for q, sq in ((a, 1), (b, -1)):
                    if p != "0" and q != "0":
                        K[idx[p], idx[q]] += sp * sq * y
        elif kind == "L":
            j = N + pos[e[0]]
            for p, sp in ((a, 1), (b, -1)):
                if p != "0":
                    K[idx[p], j] += sp
                    K[j, idx[p]] -= sp
            K[j, j] += s * v
    for e in el:
        if e[0][0] == "K":
            i, j = N + pos[e[1]], N + pos[e[2]]
            mutual = mp.mpf(e[3]) * mp.sqrt(mp.mpf(inds[pos[e[1]]][3]) * mp.mpf(inds[pos[e[2]]][3]))
            K[i, j] += s * mutual
            K[j, i] += s * mutual
    rhs = mp.matrix(N + m, 1)
    rhs[idx[port]] = 1
    return complex(mp.lu_solve(K, rhs)[idx[port]])


@pytest.mark.parametrize("name", sorted(CASES))
def test_extreme_values_right_or_refused(tmp_path, name):
    text, port, refused = CASES[name]
    path = tmp_path / f"{name}.cir"
    path.write_text(text)
    p = subprocess.run([sys.executable, "-m", "pris_cosim", "frf", "--netlist", str(path), "--port", port,
                        "--fmin", "10", "--fmax", "1e6", "--points", "3", "--json"],
                       capture_output=True, text=True, timeout=60)
    if refused:
        assert p.returncode == 2 and p.stdout == ""
        lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and f"element {refused!r}" in lines[0]
        return
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    z = out["responses"]["Zin"]
    for f, re, im in zip(out["frequency_hz"], z["re"], z["im"]):
        ref = reference_zin(text, port, f)
        assert abs(complex(re, im) - ref) <= 1e-6 * abs(ref), (f, complex(re, im), ref)
        # the damping (real part) too, wherever it is above rounding of the whole
        if abs(ref.real) > 1e-9 * abs(ref):
            assert abs(re - ref.real) <= 1e-6 * abs(ref.real) + 1e-12 * abs(ref), (f, re, ref.real)


def test_refused_case_really_is_wrong_without_the_check():
    """The refusal is not over-cautious: unchecked, the damping of that circuit comes out wrong."""
    from pris_cosim.frf.response import frequency_response
    from pris_cosim.circuits.netlist import parse_netlist

    text, port, _ = CASES["tiny_R_series"]
    z = frequency_response(parse_netlist(text), port, [1e5])["Zin"][0]
    ref = reference_zin(text, port, 1e5)
    assert abs(z.real - ref.real) > 1e3 * abs(ref.real)


@pytest.mark.parametrize("model", ["two-section", "three-section", "cascade-4", "hv-4section",
                                   "hv-6section-passive"])
def test_built_in_models_pass_the_check(model):
    m = get_model(model)
    import numpy as np

    worst = check_response_set(m.response_set(), np.logspace(-2, 8, 40))
    assert worst < 1e-5


def test_check_names_the_element():
    from pris_cosim.models.builtin import Configuration, ResponseSet
    from pris_cosim.frf.response import Response
    from pris_cosim.circuits.netlist import parse_netlist

    c = parse_netlist(CASES["tiny_R_series"][0])
    rs = ResponseSet(c, [Configuration("x", "n1", (), (Response("Zin"),))])
    with pytest.raises(CircuitError, match="'R1'"):
        check_response_set(rs, [1e5])
