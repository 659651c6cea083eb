"""``pris-cosim estimate`` with its defaults: right, or it says it is not.

Targets are drawn here and computed by a separate nodal solver written in
this file (admittance matrix of R, C and coupled L branches, one complex
solve per frequency), not by the estimation's state-space / pole-residue path.

Stated accuracy (two-section, defaults): every parameter within 1 % whenever
the verdict says ``converged``; at least 7 of 10 random targets converge.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from estimation import cli
from estimation.parameters import ParameterSet
from pris_cosim.models.builtin import get_model


# ---------------------------------------------------------------- independent reference solver
def nodal_voltages(circuit, values: dict, port: str, f: np.ndarray) -> dict[str, np.ndarray]:
    """Node voltages for 1 A injected at ``port``: Y(jw) V = e_port with Y built from the element list."""
    elems = circuit.elements
    nodes = sorted({n for e in elems if e.kind in "RLC" for n in e.nodes} - {"0"})
    idx = {n: i for i, n in enumerate(nodes)}
    inds = [e for e in elems if e.kind == "L"]
    lpos = {e.name.lower(): i for i, e in enumerate(inds)}
    Lm = np.diag([values[e.name.lower()] for e in inds]).astype(float)
    for e in elems:
        if e.kind == "K":
            a, b = (lpos[n.lower()] for n in e.nodes)
            Lm[a, b] = Lm[b, a] = values[e.name.lower()] * math.sqrt(Lm[a, a] * Lm[b, b])
    AL = np.zeros((len(nodes), len(inds)))
    for j, e in enumerate(inds):
        p, m = e.nodes
        if p != "0":
            AL[idx[p], j] += 1
        if m != "0":
            AL[idx[m], j] -= 1
    out = np.zeros((len(nodes), f.size), complex)
    for k, fk in enumerate(f):
        s = 2j * math.pi * fk
        Y = AL @ np.linalg.inv(s * Lm) @ AL.T if inds else np.zeros((len(nodes),) * 2, complex)
        Y = Y.astype(complex)
        for e in elems:
            if e.kind in "RC":
                y = 1 / values[e.name.lower()] if e.kind == "R" else s * values[e.name.lower()]
                p, m = e.nodes
                for a, sa in ((p, 1), (m, -1)):
                    for b, sb in ((p, 1), (m, -1)):
                        if a != "0" and b != "0":
                            Y[idx[a], idx[b]] += sa * sb * y
        rhs = np.zeros(len(nodes), complex)
        rhs[idx[port]] = 1.0
        out[:, k] = np.linalg.solve(Y, rhs)
    return {n: out[i] for n, i in idx.items()}


def two_section_target(rng: np.random.Generator) -> dict[str, float]:
    """Random two-section winding with R2 = R1, C2 = C1 inside the default bounds."""
    L1, L2 = 10 ** rng.uniform(0.5, 1.5), 10 ** rng.uniform(1.5, 2.5)
    k = rng.uniform(0.5, 0.95)
    return {"R1": 10 ** rng.uniform(0.5, 1.5), "C1": 10 ** rng.uniform(-9.5, -8.5), "L1": L1, "L2": L2,
            "M12": k * math.sqrt(L1 * L2)}


def draw_target(model, rng: np.random.Generator, spread: float = 2.0) -> tuple[dict, dict]:
    """Random target of the default estimation vector: ``(drawn parameters, every circuit value)``.

    Each varying parameter is drawn log-uniformly within a factor ``spread`` of its nominal value and
    inside its default bounds; a coupling (``K``, or the ``M`` of a coupling element) moves its
    coefficient uniformly within +-2 % inside its bounds. Tied parameters follow their ties.
    """
    params = cli._parameter_set(model, {})
    u_nominal = params.to_unit(params.values())
    u = np.empty_like(u_nominal)
    for i, name in enumerate(params.varying):
        p = params[name]
        if p.kind in ("K", "M"):
            k = p.min + u_nominal[i] * (p.max - p.min)  # couplings map linearly to the cube
            k = float(np.clip(k * rng.uniform(0.98, 1.02), p.min, p.max))
            u[i] = (k - p.min) / (p.max - p.min)
        else:
            v = float(p.value)
            lo, hi = max(p.min, v / spread), min(p.max, v * spread)
            u[i] = p.to_unit(10 ** rng.uniform(math.log10(lo), math.log10(hi)))
    values = params.values(u)
    drawn = {k: float(values[k]) for k in params.varying}
    return drawn, {k: float(v) for k, v in params.overrides(u).items()}


def target_responses(model, values: dict, f: np.ndarray) -> dict[str, np.ndarray]:
    """Every configuration's responses of ``model`` at ``values``, by the nodal solver above."""
    out = {}
    for cfg in model.configurations.values():
        circuit = model.circuit.shorted(cfg.shorts) if cfg.shorts else model.circuit
        v = nodal_voltages(circuit, circuit.resolve(values, check=False), cfg.port, f)
        for r in cfg.responses:
            if r.node is None:
                out[r.name] = v[cfg.port]
            else:
                num = v[r.node] - (v[r.minus] if r.minus and r.minus != "0" else 0.0)
                out[r.name] = num / v[cfg.port]
    return out


def write_responses(path, f, resp):
    cols = ["frequency_hz"] + [f"{r}_{p}" for r in resp for p in ("re", "im")]
    rows = [",".join(cols)]
    for i in range(f.size):
        rows.append(",".join([repr(float(f[i]))] + [repr(float(getattr(resp[r][i], p))) for r in resp
                                                     for p in ("real", "imag")]))
    path.write_text("\n".join(rows) + "\n")


# ---------------------------------------------------------------- smallest config
def _errors(out):
    return {k: abs(v) for k, v in out["errors_percent"].items()}


@pytest.mark.slow
def test_smallest_config_frequency_is_right_and_says_so():
    out = cli.run_estimate({"model": "two-section"}, progress=False)
    assert max(_errors(out).values()) < 1.0, out["errors_percent"]
    assert out["converged"] is True and out["non_identifiable"] == []
    assert set(out["uncertainty"]) == set(out["estimate"])
    assert all(0 <= u < 0.01 for u in out["uncertainty"].values())


@pytest.mark.slow
def test_smallest_config_time_within_1pct():
    out = cli.run_estimate({"model": "two-section", "approach": "time", "duration": 0.05, "fs": 200e3},
                           progress=False)
    assert max(_errors(out).values()) < 1.0, out["errors_percent"]
    assert out["converged"] is True


@pytest.mark.slow
def test_port_only_record_names_what_it_cannot_determine(tmp_path):
    """Zin alone with all seven values free: equivalent circuits exist; the verdict says so, exit 0, one warning.

    The restarts of the defaults find different circuits with the same ``Zin`` and name every parameter;
    a single restart cannot know, and a value at its bound then keeps it from claiming convergence.
    """
    cfg = tmp_path / "zin.json"
    cfg.write_text(json.dumps({"model": "two-section", "responses": ["Zin"], "ties": {}}))
    p = subprocess.run([sys.executable, "-m", "pris_cosim", "estimate", "--config", str(cfg), "--json"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0
    out = json.loads(p.stdout)
    bad = max(_errors(out).values()) > 1.0
    if bad:  # a wrong answer must not look right
        assert out["converged"] is False and out["non_identifiable"]
        warnings = [ln for ln in p.stderr.splitlines() if ln.startswith("warning:")]
        assert len(warnings) == 1 and "not converged" in warnings[0]


# ---------------------------------------------------------------- estimate = scored model
def test_reported_values_are_the_scored_model():
    """A mutual inductance beyond sqrt(L1 L2) is never reported: the coupling lives in the parametrisation."""
    ps = ParameterSet.from_model(get_model("two-section"), ties={"R2": "R1", "C2": "C1"})
    U = np.random.default_rng(3).random((400, len(ps.varying)))
    ev = ps.evaluate(U)
    k = ev.values["M12"] / np.sqrt(ev.values["L1"] * ev.values["L2"])
    assert np.all(np.abs(k) < 1)
    # explicit bounds in H: a repaired point reports the repaired mutual inductance
    ps2 = ParameterSet.from_model(get_model("two-section"), bounds={"M12": (3.0, 300.0)})
    u = ps2.to_unit({"R1": 10, "R2": 10, "C1": 1e-9, "C2": 1e-9, "L1": 48, "L2": 30, "M12": 194})
    ev2 = ps2.evaluate(u)
    assert ev2.repaired[0]
    assert ev2.values["M12"] / math.sqrt(48 * 30) < 1
    assert ev2.values["M12"] / math.sqrt(48 * 30) == pytest.approx(ev2.overrides["K12"], rel=1e-12)


# ---------------------------------------------------------------- independent targets
def test_reference_solver_agrees_with_thesis_values():
    """The test's own solver reproduces the design note's |Zin| of Table 4.2 (ngspice-checked)."""
    m = get_model("two-section")
    v = m.circuit.resolve(check=False)
    z = nodal_voltages(m.circuit, v, "in", np.array([10.0, 1e3, 1e5]))["in"]
    assert np.abs(z) == pytest.approx([10686.02, 319612.3, 3185.12], rel=1e-6)


@pytest.mark.slow
@pytest.mark.long
def test_two_section_ten_independent_targets(tmp_path):
    """Ten random windings, responses from the nodal solver above; ``estimate`` with its defaults.

    Stated accuracy: on every target, each parameter is within 1 % or the verdict names it
    (``non_identifiable``) or says ``converged: false``; at least 7 of 10 converge (measured: 7,
    each with every parameter within 1e-4 %); C1, L1, L2, M12 are within 1 % on at least 9
    (measured: 10). The 100 compared points are the target file's own frequencies. (R1 shows only in the depth of resonances sharper than the
    200-point grid; against the noise floor read off the data it is named as not identifiable.)
    """
    m = get_model("two-section")
    rng = np.random.default_rng(2026)
    f = np.logspace(np.log10(20), np.log10(9e3), 100)
    good = converged = 0
    for i in range(10):
        t = two_section_target(rng)
        vals = m.circuit.resolve({"R1": t["R1"], "R2": t["R1"], "C1": t["C1"], "C2": t["C1"], "L1": t["L1"],
                                  "L2": t["L2"], "M12": t["M12"]}, check=False)
        v = nodal_voltages(m.circuit, vals, "in", f)
        resp = {"Zin": v["in"], "R1in": (v["in"] - v["mid"]) / v["in"], "R2in": v["mid"] / v["in"]}
        path = tmp_path / f"t{i}.csv"
        write_responses(path, f, resp)
        out = cli.run_estimate({"model": "two-section", "target": {"kind": "responses-csv", "path": str(path)},
                                "frequency": {"points": 100}, "seed": i + 1}, progress=False)
        err = {k: abs(out["estimate"][k] - t[k]) / t[k] * 100 for k in t}
        wrong = [k for k, e in err.items() if not e < 1.0]
        assert out["converged"] is False or not wrong, (i, err, out["convergence_reason"])
        assert all(k in out["non_identifiable"] for k in wrong) or not out["converged"], (i, err)
        good += all(err[k] < 1.0 for k in ("C1", "L1", "L2", "M12"))
        converged += bool(out["converged"])
    assert good >= 9 and converged >= 7


def _ten_targets(name: str, tmp_path, points: int, budget: dict | None = None) -> list[dict]:
    """Ten targets of ``name`` (:func:`draw_target`, nodal solver above), each estimated with the defaults."""
    from estimation.estimate import default_band

    model = get_model(name)
    lo, hi = default_band(model, next(iter(model.configurations.values())))
    f = np.logspace(np.log10(lo), np.log10(hi), points)
    rng = np.random.default_rng(2026)
    rows = []
    for i in range(10):
        t, full = draw_target(model, rng)
        path = tmp_path / f"{name}-{i}.csv"
        write_responses(path, f, target_responses(model, full, f))
        cfg = {"model": name, "target": {"kind": "responses-csv", "path": str(path)}, "seed": i + 1}
        if budget:
            cfg["budget"] = budget
        out = cli.run_estimate(cfg, progress=False)
        err = {k: abs(out["estimate"][k] - v) / abs(v) * 100 for k, v in t.items() if v != 0}
        wrong = [k for k, e in err.items() if not e < 1.0]
        rows.append({"wrong": wrong, "converged": out["converged"], "non_identifiable": out["non_identifiable"],
                     "reason": out["convergence_reason"], "worst": max(err.values())})
    return rows


@pytest.mark.slow
@pytest.mark.long
@pytest.mark.parametrize("name", ["three-section", "cascade-4"])
def test_one_port_models_ten_independent_targets(name, tmp_path):
    """Ten random windings per one-port model, ``Zin`` from the nodal solver above, ``estimate`` with its defaults.

    Targets: every parameter of the default estimation vector log-uniform within a factor 2 of
    the model's value and inside the default bounds (three-section: Table 4.8), couplings within
    +-2 %. Stated accuracy: every answer is right (every parameter within 1 %) or says it is not
    (``converged: false`` or the wrong parameters named as not identifiable); at least 9 of 10
    are right and converged (measured: 10 of 10 for both, worst error below 1e-6 %).
    """
    rows = _ten_targets(name, tmp_path, points=200)
    for i, r in enumerate(rows):
        assert not r["wrong"] or r["converged"] is False or all(k in r["non_identifiable"] for k in r["wrong"]), (i, r)
    assert sum(not r["wrong"] and r["converged"] for r in rows) >= 9, rows


@pytest.mark.parametrize("name", ["hv-4section"]
                         # the six-section structures, those with the cable's other couplings, and the ladders: long
                         # runs only
                         + [pytest.param(n, marks=pytest.mark.long)
                            for n in ("hv-6section", "hv-6section-passive", "hv-4section-cab2a", "hv-4section-cab2b",
                                      "hv-6section-freqdep")])
@pytest.mark.slow
def test_two_winding_models_ten_targets_say_so(name, tmp_path):
    """Ten random targets per two-winding model (33-43 parameters), six responses from the nodal solver above.

    The defaults fit all six configurations of the file jointly. With a one-second budget they
    cannot find 33-43 parameters, and the stated accuracy is the honest one: no answer claims
    ``converged`` with a parameter more than 1 % off that the verdict does not name. (Without a
    budget, ``benchmarks/bench_estimate_defaults.py`` measures 5-8 minutes per target on two
    cores, still not converged: the thesis's own Case Studies needed the PSO sweep of the study.)
    """
    rows = _ten_targets(name, tmp_path, points=40, budget={"max_time_s": 1})
    for i, r in enumerate(rows):
        assert not r["wrong"] or r["converged"] is False or all(k in r["non_identifiable"] for k in r["wrong"]), (i, r)
