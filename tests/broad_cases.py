"""Broad diagnosis cases written from physics: a winding cascade solved by its own nodal equations.

Nothing here is imported from pris-cosim: the cascade's modified nodal
equations (node voltages and inductor currents, the inductance matrix with
couplings), the effects and the file writers are written out below, so a
diagnosis checked against these cases is checked against other code.

A draw (:func:`draw`) is a winding of 3-10 sections: inductances, series
resistances, series and ground capacitances drawn per section, couplings
``k_ij = rho^|i-j|`` with a random decay ``rho`` (a Kac-Murdock-Szego matrix,
positive definite for ``|rho| < 1``). Its design netlist is the truth with
every value moved within 10 % (a tolerance of 20 % covers it), on a grid from
100 Hz-10 kHz to 1-10 MHz with 200-1000 points, complex noise of 0.1-2 %
(RMS of ``ln H``), written as CSV or Touchstone ``.s1p``. The hidden effect
(``EFFECTS``) is one of:

``none``
    nothing (truth: no cause, no drift).
``skin``
    every section's resistance replaced by a round conductor's internal
    impedance ``R_dc (x/2) J0(x)/J1(x)``, ``x = (1 - j) a / delta``
    (truth: ``skin-effect``).
``coreloss``
    the inductance matrix times a lamination's ``tanh(q)/q``,
    ``q = (1 + j) d / (2 delta_core)`` (truth: ``core-loss``).
``cg_scale``
    every capacitance to ground times 1.4-1.8 (truth: drift of the group).
``local``
    one capacitance to ground or one series capacitance times 1.8-3 (truth:
    drift of that value).
``split``
    one section made two, the inductance shared 35-65 %, the series
    capacitance split, a new node with its own capacitance to ground and
    couplings continuing the decay (truth: ``missing-section``).
``beyond``
    one resistance or inductance moved 1.6-2.5x (truth: drift of that value).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.special import jve

EFFECTS = ("none", "skin", "coreloss", "cg_scale", "local", "split", "beyond")
TRUTH_CAUSES = {"skin": ["skin-effect"], "coreloss": ["core-loss"], "split": ["missing-section"]}


@dataclass
class Winding:
    """A cascade: section ``i`` joins node ``i`` to node ``i + 1`` (the last to ground); node 0 is the port."""

    R: np.ndarray
    L: np.ndarray
    Cs: np.ndarray
    Cg: np.ndarray
    K: np.ndarray  # coupling coefficients, ones on the diagonal

    @property
    def n(self) -> int:
        return self.R.size

    def inductance(self) -> np.ndarray:
        s = np.sqrt(self.L)
        return self.K * np.outer(s, s)


def zin(w: Winding, f: np.ndarray, r_of_f=None, l_factor=None) -> np.ndarray:
    """Driving-point impedance at node 0 (Ohm): one modified nodal solve per frequency.

    ``r_of_f(f) -> (n,)`` complex series impedances replacing ``R``; ``l_factor(f)`` a complex factor on the
    inductance matrix.
    """
    n = w.n
    Lm = w.inductance()
    out = np.empty(f.size, complex)
    A = np.zeros((n, n))  # node-branch incidence: branch i leaves node i, enters node i+1 (ground past the last)
    for i in range(n):
        A[i, i] = 1.0
        if i + 1 < n:
            A[i + 1, i] = -1.0
    for m, fk in enumerate(f):
        s = 2j * np.pi * fk
        Y = np.zeros((n, n), complex)
        for i in range(n):
            Y[i, i] += s * w.Cg[i]
            a, b = i, i + 1
            Y[a, a] += s * w.Cs[i]
            if b < n:
                Y[b, b] += s * w.Cs[i]
                Y[a, b] -= s * w.Cs[i]
                Y[b, a] -= s * w.Cs[i]
        Zb = np.diag(r_of_f(fk) if r_of_f else w.R.astype(complex)) + s * Lm * (l_factor(fk) if l_factor else 1.0)
        M = np.block([[Y, A], [A.T, -Zb]])
        rhs = np.zeros(2 * n, complex)
        rhs[0] = 1.0
        out[m] = np.linalg.solve(M, rhs)[0]
    return out


def skin_impedance(R: np.ndarray, f_skin: float):
    """Round conductor: ``Z = R_dc (x/2) J0(x)/J1(x)``, ``x = (1 - j) a / delta``, ``a = delta`` at ``f_skin``."""
    def z(fk: float) -> np.ndarray:
        x = (1 - 1j) * np.sqrt(fk / f_skin)
        return R * (x / 2) * jve(0, x) / jve(1, x)  # the exponential scalings of jve cancel in the ratio
    return z


def lamination_factor(f_core: float):
    """Lamination: ``tanh(q)/q``, ``q = (1 + j) d / (2 delta)``, ``d = delta`` at ``f_core``."""
    def g(fk: float) -> complex:
        q = (1 + 1j) * 0.5 * np.sqrt(fk / f_core)
        return complex(np.tanh(q) / q)
    return g


@dataclass
class Case:
    name: str
    effect: str
    frequency_hz: np.ndarray
    z: np.ndarray
    netlist: str
    port: str
    causes: list[str]
    drift: list[str] | None
    noise: float
    fmt: str
    extra: dict = field(default_factory=dict)
    clean: np.ndarray | None = None  # the response without noise
    design: Winding | None = None
    truth: Winding | None = None  # the winding the response is of (a split: one section more)


def _netlist(w: Winding, title: str) -> str:
    lines = [f"* {title}"]
    n = w.n
    node = lambda i: "0" if i >= n else f"n{i + 1}"  # noqa: E731
    for i in range(n):
        lines += [f"R{i + 1} {node(i)} x{i + 1} {w.R[i]:.6g}", f"L{i + 1} x{i + 1} {node(i + 1)} {w.L[i]:.6g}",
                  f"C{i + 1} {node(i)} {node(i + 1)} {w.Cs[i]:.6g}"]
    lines += [f"Cg{i + 1} {node(i)} 0 {w.Cg[i]:.6g}" for i in range(n)]
    lines += [f"K{i + 1}_{j + 1} L{i + 1} L{j + 1} {w.K[i, j]:.6g}" for i in range(n) for j in range(i + 1, n)]
    return "\n".join(lines) + "\n"


def _random_winding(rng: np.random.Generator, n: int) -> Winding:
    rho = rng.uniform(0.45, 0.9)
    idx = np.arange(n)
    return Winding(R=rng.uniform(0.2, 1.0, n), L=rng.uniform(1e-3, 5e-3, n), Cs=rng.uniform(0.3e-9, 2e-9, n),
                   Cg=rng.uniform(0.3e-9, 2e-9, n), K=rho ** np.abs(idx[:, None] - idx[None, :]))


def _split(w: Winding, j: int, a: float, rng: np.random.Generator) -> Winding:
    """Section ``j`` as two: inductance shares ``a``, ``1 - a`` (with their mutual), a new node with its own Cg."""
    n = w.n
    rho = float(w.K[0, 1]) if n > 1 else 0.7
    keep = 1 + 2 * rho * np.sqrt(a * (1 - a))  # the two halves with their mutual keep the section's inductance
    L1, L2 = w.L[j] * a / keep, w.L[j] * (1 - a) / keep
    R = np.insert(w.R, j + 1, w.R[j] * (1 - a))
    R[j] = w.R[j] * a
    L = np.insert(w.L, j + 1, L2)
    L[j] = L1
    Cs = np.insert(w.Cs, j + 1, w.Cs[j] * rng.uniform(1.5, 2.5))
    Cs[j] = w.Cs[j] * rng.uniform(1.5, 2.5)
    Cg = np.insert(w.Cg, j + 1, w.Cg[j] * rng.uniform(0.5, 1.0))
    idx = np.arange(n + 1)
    K = rho ** np.abs(idx[:, None] - idx[None, :])
    return Winding(R, L, Cs, Cg, K)


def draw(seed: int, effect: str | None = None, points: int | None = None, k: int = 0) -> Case:
    """One case from ``seed`` (the effect drawn from ``EFFECTS`` unless given; ``points`` replaces the drawn number
    of frequencies, the rest of the draw unchanged).

    ``k > 0`` is another, independent draw of the same seed's effect (the winding, grid, noise and the effect's
    size drawn again from the generator ``[seed, k]``); ``k = 0`` is the seed's own draw.
    """
    if k and effect is None:
        effect = effect_of(seed)
    rng = np.random.default_rng(seed if k == 0 else [seed, k])
    effect = effect or EFFECTS[int(rng.integers(len(EFFECTS)))]
    n = int(rng.integers(3, 11))
    truth = _random_winding(rng, n)
    lo, hi, n_f = rng.uniform(2, 4), rng.uniform(6, 7), int(rng.integers(200, 1001))
    f = np.logspace(lo, hi, points or n_f)
    noise = float(np.exp(rng.uniform(np.log(1e-3), np.log(2e-2))))
    design = Winding(*(v * rng.uniform(0.9, 1.1, v.shape) for v in (truth.R, truth.L, truth.Cs, truth.Cg)),
                     K=truth.K.copy())
    causes, drift, r_of_f, l_factor, extra = TRUTH_CAUSES.get(effect, []), [], None, None, {}
    if effect == "skin":
        extra["f_skin"] = float(10 ** rng.uniform(np.log10(f[0]) + 1, 5.5))
        r_of_f = skin_impedance(truth.R, extra["f_skin"])
    elif effect == "coreloss":
        extra["f_core"] = float(10 ** rng.uniform(3.5, 5))
        l_factor = lamination_factor(extra["f_core"])
    elif effect == "cg_scale":
        truth.Cg = truth.Cg * rng.uniform(1.4, 1.8)
        drift = [f"Cg{i + 1}" for i in range(n)]
    elif effect == "local":
        i = int(rng.integers(n))
        which = "Cg" if rng.random() < 0.5 else "C"
        arr = truth.Cg if which == "Cg" else truth.Cs
        arr[i] *= rng.uniform(1.8, 3.0)
        drift = [f"{which}{i + 1}"]
    elif effect == "beyond":
        i = int(rng.integers(n))
        which = "R" if rng.random() < 0.5 else "L"
        arr = truth.R if which == "R" else truth.L
        arr[i] *= rng.uniform(1.6, 2.5) ** (1 if rng.random() < 0.5 else -1)
        drift = [f"{which}{i + 1}"]
    elif effect == "split":
        j = int(rng.integers(n))
        extra["split"] = j + 1
        truth = _split(truth, j, rng.uniform(0.35, 0.65), rng)
        drift = None
    clean = zin(truth, f, r_of_f, l_factor)
    z = clean * np.exp(noise / np.sqrt(2) * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)))
    fmt = "s1p" if rng.random() < 0.3 else "csv"
    name = f"broad_{seed}_{effect}" + (f"_d{k}" if k else "")
    return Case(name, effect, f, z, _netlist(design, f"design, {n} sections"), "n1", causes,
                None if effect in ("skin", "coreloss", "split") else drift, noise, fmt, extra, clean, design, truth)


def effect_of(seed: int) -> str:
    """The effect ``seed``'s own draw hides (:func:`draw` with ``k = 0``)."""
    return EFFECTS[int(np.random.default_rng(seed).integers(len(EFFECTS)))]


def _solve_many(R, L, Cs, Cg, K, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A winding without effects at every frequency in one batched solve: the port impedance (Ohm) and the
    solution ``x`` (node voltages, then branch currents) for a unit current into node 0."""
    n = R.size
    s = 2j * np.pi * f[:, None, None]
    conn = np.eye(n) - np.eye(n, k=-1)  # incidence: branch i leaves node i, enters node i+1
    ycs = Cs[:-1]
    Yc = np.diag(Cg + Cs + np.concatenate([[0.0], ycs])) - np.diag(ycs, 1) - np.diag(ycs, -1)
    M = np.zeros((f.size, 2 * n, 2 * n), complex)
    M[:, :n, :n] = s * Yc
    M[:, :n, n:] = conn
    M[:, n:, :n] = conn.T
    M[:, n:, n:] = -(np.diag(R) + s * (K * np.sqrt(np.outer(L, L))))
    rhs = np.zeros((f.size, 2 * n, 1), complex)
    rhs[:, 0, 0] = 1.0
    x = np.linalg.solve(M, rhs)[:, :, 0]
    return x[:, 0], x


def _log_z_and_gradient(v: np.ndarray, K: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``ln Z`` of the values ``v = [R, L, Cs, Cg]`` and its derivatives by ``ln v`` (columns).

    The nodal matrix ``M`` is symmetric, so ``dZ = -x^T dM x`` with ``x = M^-1 e_0`` (one solve for all).
    """
    n = K.shape[0]
    R, L, Cs, Cg = v[:n], v[n:2 * n], v[2 * n:3 * n], v[3 * n:]
    z, x = _solve_many(R, L, Cs, Cg, K, f)
    s = 2j * np.pi * f[:, None]
    u, i = x[:, :n], x[:, n:]
    du = u - np.concatenate([u[:, 1:], np.zeros((f.size, 1))], axis=1)  # across section k: node k minus node k+1
    lm = K * np.sqrt(np.outer(L, L))
    dz = np.concatenate([R * i ** 2, s * i * (i @ lm), -s * Cs * du ** 2, -s * Cg * u ** 2], axis=1)
    return np.log(z), dz / z[:, None]


#: An effect whose :func:`signature` is below this is hidden in the noise: a likelihood-ratio test of two added
#: parameters at a false-alarm rate of 1e-3 (threshold 13.8) finds a signature of 25 nine times in ten, and one of
#: 10 only a third of the time.
VISIBLE = 25.0


def signature(case: Case, tolerance: float = 0.2, max_nfev: int = 400, steps: int = 8) -> float:
    """How far the hidden effect stands out of the noise once the design's own model has taken what it can.

    The design's structure (no effect, no split) with every ``R``, ``L``, ``Cs``, ``Cg`` free within the
    tolerance (``|ln(v/d)| <= ln(1 + tolerance)``) is fitted by least squares to the response without noise;
    returned is the misfit left in units of the noise, the non-centrality
    ``lambda = sum_k |ln Z_k - ln Z'_k|^2 / (sigma^2 / 2)`` of a chi-square test of the design model against the
    data (``sigma`` the noise's RMS of ``ln Z``, half of it in each of the real and imaginary parts). The fit is
    :func:`within_tolerance`'s; a local fit, so ``lambda`` is an upper bound of the least misfit, and an effect
    called hidden (small ``lambda``) is hidden.
    """
    return within_tolerance(case, tolerance, max_nfev, steps)[0]


#: Draws of one seed tried by :func:`visible_draw` before it gives up.
MAX_DRAWS = 50


def visible_draw(seed: int, effect: str | None = None, max_draws: int = MAX_DRAWS) -> tuple[int, Case, float]:
    """The first draw ``k = 0, 1, ...`` of ``seed`` (:func:`draw`) whose effect shows: ``(k, case, signature)``.

    A draw whose :func:`signature` is below :data:`VISIBLE` hides its effect in the noise: the design's own model
    within the tolerance fits it, so no diagnosis can name it, and such a draw measures the noise, not the
    diagnosis. The seed's own draw (``k = 0``) is kept when its effect shows, and always when it hides nothing
    (``none``). Which draw is taken is decided here, from the generator's solver alone, before any diagnosis sees
    it. Raises ``ValueError`` when none of ``max_draws`` draws shows.
    """
    for k in range(max_draws):
        case = draw(seed, effect, k=k)  # the seed's own draw as the benchmark draws it (``effect`` as given)
        if case.effect == "none":
            return k, case, 0.0
        lam = signature(case)
        if lam >= VISIBLE:
            return k, case, lam
    raise ValueError(f"seed {seed}: no draw of {max_draws} shows its {effect} effect")


def within_tolerance(case: Case, tolerance: float = 0.2, max_nfev: int = 400, steps: int = 8
                     ) -> tuple[float, Winding]:
    """The design's structure fitted within the tolerance to the clean response: ``(lambda, winding)``.

    Two local fits, the smaller misfit kept: one from the truth's values clipped to the tolerance (else the
    design's), and, where the truth has the design's structure, a continuation from the truth itself (misfit
    zero): the bounds closed from the truth's values onto the tolerance in ``steps`` steps, each fit started from
    the last. A value far off (a capacitance doubled) clipped to its edge leaves the others in another basin than
    the one the model within the tolerance may reach by moving them together; the continuation follows that basin.
    The winding returned has every value within the tolerance (``lambda`` is its misfit, see :func:`signature`).
    """
    d = case.design
    n = d.n
    t = case.truth
    tau = np.log1p(tolerance)
    base = np.concatenate([d.R, d.L, d.Cs, d.Cg])
    x0 = np.zeros(base.size)
    same = t is not None and t.n == n
    if same:
        x_truth = np.log(np.concatenate([t.R, t.L, t.Cs, t.Cg]) / base)
        x0 = np.clip(x_truth, -tau, tau)
    target = np.log(case.clean)

    last: dict[bytes, tuple] = {}

    def solved(x):  # the residuals and their Jacobian from one solve (least_squares asks for both at each x)
        key = x.tobytes()
        if key not in last:
            lz, g = _log_z_and_gradient(base * np.exp(x), d.K, case.frequency_hz)
            e = lz - target
            e.imag = (e.imag + np.pi) % (2 * np.pi) - np.pi
            last.clear()
            last[key] = (np.concatenate([e.real, e.imag]), np.concatenate([g.real, g.imag]))
        return last[key]

    def res(x):
        return solved(x)[0]

    def jac(x):
        return solved(x)[1]

    best, x_best = res(x0), x0
    fit = least_squares(res, x0, jac=jac, bounds=(-tau, tau), max_nfev=max_nfev, x_scale=0.05)
    if fit.cost * 2 < best @ best:
        best, x_best = fit.fun, fit.x
    if same:
        x = x_truth
        for s in np.linspace(0.0, 1.0, steps + 1)[1:]:
            lo = -tau + (1 - s) * np.minimum(0.0, x_truth + tau)
            hi = tau + (1 - s) * np.maximum(0.0, x_truth - tau)
            x = least_squares(res, np.clip(x, lo, hi), jac=jac, bounds=(lo, hi), max_nfev=max_nfev // 2,
                              x_scale=0.05).x
        x = np.clip(x, -tau, tau)
        r = res(x)
        if r @ r < best @ best:
            best, x_best = r, x
    v = base * np.exp(x_best)
    return float(best @ best / (case.noise ** 2 / 2)), Winding(*np.split(v, 4), d.K)


def reported_drift(drift: list[dict], truth: list[str] | None = None) -> set[str]:
    """The names a diagnosis reports beyond the tolerance, as the truth lists them: a group's drift by its members
    (less a series capacitance reported with the ground capacitance it is in parallel with). A value reported with
    others of its kind across the same two nodes (``parallel``: the last section's series capacitance and its
    node's capacitance to ground) is one capacitance to the terminals: it stands for the one ``truth`` names."""
    out: set[str] = set()
    for d in drift:
        if d.get("members"):
            out.update(m for m in d["members"] if not (m in d.get("in_parallel", []) and not m.lower().startswith("cg")))
        else:
            alias = [p for p in d.get("parallel", []) if truth and p in truth and d["name"] not in truth]
            out.add(alias[0] if alias else d["name"])
    return out


def write(case: Case, directory: Path) -> tuple[Path, Path]:
    """The measured file (CSV ``frequency_hz,Zin_mag,Zin_phase_deg`` or a Touchstone ``.s1p`` in 50 Ohm RI) and
    the design netlist."""
    directory.mkdir(parents=True, exist_ok=True)
    net = directory / f"{case.name}.cir"
    net.write_text(case.netlist)
    if case.fmt == "csv":
        data = directory / f"{case.name}.csv"
        rows = np.column_stack([case.frequency_hz, np.abs(case.z), np.degrees(np.angle(case.z))])
        np.savetxt(data, rows, delimiter=",", header="frequency_hz,Zin_mag,Zin_phase_deg", comments="", fmt="%.9e")
    else:
        data = directory / f"{case.name}.s1p"
        s = (case.z - 50.0) / (case.z + 50.0)
        lines = ["! one-port reflection of a winding, independent nodal solver", "# Hz S RI R 50"]
        lines += [f"{fk:.9e} {v.real:.12e} {v.imag:.12e}" for fk, v in zip(case.frequency_hz, s)]
        data.write_text("\n".join(lines) + "\n")
    return data, net


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="write broad cases (seed effect pairs) to a folder")
    ap.add_argument("out")
    ap.add_argument("seeds", nargs="+", type=int)
    ap.add_argument("--effect", choices=EFFECTS)
    a = ap.parse_args()
    for sd in a.seeds:
        c = draw(sd, a.effect)
        d, n = write(c, Path(a.out))
        print(c.name, d, n, c.causes, c.drift, f"{c.noise:.3%}", c.frequency_hz.size)
