"""Is a hidden cause detectable at all? Decided with the reference solver, not with the diagnosis.

A case whose truth has one section more than its baseline can only be
diagnosed if no network of the baseline's structure reproduces the truth
within the noise; the same holds for a frequency-dependent effect that
constant values of the baseline's elements absorb (``target="truth"``). This module fits the baseline's structure (its R, L and C
values free in log scale, couplings as given) to the truth's responses
without noise, using only :mod:`refsolver` and :func:`scipy.optimize.least_squares`
(no code of the diagnosis), from the baseline's values, from the exact
merge of the truth's sections (the baseline before its jitter), for an
effect (``target="truth"``) from the truth's own constant values when it
has the baseline's structure, and from twelve random starts around the merge (a local fit from one start can stop in a
poor optimum and call a case detectable that is not).

Criterion: the missing section is *undetectable* when the best fit's mean
squared complex log error on every response is below the noise's own,
``E|n|^2 = 2 s^2`` for the benchmark's noise (``s`` relative in magnitude,
``s`` rad in phase): the truth then lies within the noise of a network the
baseline's structure can reach. Hidden effects other than the missing
section are left out of both sides (they are not what is being asked about).
A fit that fails to get there leaves the case counted as detectable, so the
count of undetectable cases is a lower bound. The other effect of a compound
case with a missing section is asked about the same way, with the truth's
own sections (the section given) fitted to the whole truth; so is one effect
of a compound of two, with the truth's sections and the other effect, in the
truth's own form and parameters, fitted to the whole truth.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

import refsolver as rs


def _responses(net: rs.Net, kind: str, f: np.ndarray) -> dict[str, np.ndarray]:
    if kind in ("one-port", "design"):
        return {"Zin": rs.impedance(net, "n1", f)}
    return rs.two_winding_responses(net, f)


def best_baseline_fit(case, max_nfev: int = 400, random_starts: int = 12, target: str = "sections",
                      bound: float = float(np.log(100.0)), free: tuple[str, ...] = (), structure: str = "baseline",
                      keep: str | None = None, early: bool = False) -> dict[str, float]:
    """Fit of the baseline's structure to the truth (no noise).

    Parameters
    ----------
    case : hidden_cases.HiddenCase
        A case made with ``nets`` kept (every case of :mod:`hidden_cases`).
    max_nfev : int
        Evaluations per start.
    random_starts : int
        Starts drawn around the merge (log-normal, 40 %, fixed seed).
    target : str
        ``sections``: the truth's sections without its other effects (is a
        missing section detectable); ``truth``: the truth with every effect
        (is a frequency-dependent effect detectable).
    bound : float
        Largest ``|ln(value / baseline value)|`` of the fit (a design case:
        the values within twice the design tolerance, beyond which the
        diagnosis counts a fit as drift, not as an explanation).
    free : tuple of str
        Elements exempt from ``bound`` (a design case's drifted value).
    structure : str
        ``baseline``: the baseline's structure, from its values and the
        merge of the truth's sections (as above); ``sections``: the truth's
        own sections (a missing section given), from their values, so that
        ``target="truth"`` asks whether the other effects of a compound case
        are detectable once the section is there.
    keep : str, optional
        With ``structure="sections"``: the truth's sections with this one
        hidden effect written in as the truth has it (``nets["only:CAUSE"]``
        of a one-port or design case), values free, so that
        ``target="truth"`` asks whether the compound's other effect can be
        told apart once this one is in the model.
    early : bool
        Stop at the first start that reaches the noise (the answer,
        undetectable, is then known; ``cost`` is that start's, not the best).

    Returns
    -------
    dict
        ``cost`` (largest over responses of the mean squared complex log
        error), ``noise`` (``2 s^2``), ``detectable`` (bool).
    """
    f = case.frequency_hz
    truth = _responses(case.nets[target], case.kind, f)
    home = case.nets[(f"only:{keep}" if keep else "sections") if structure == "sections" else "merged"]
    names = [e[0] for e in (home if structure == "sections" else case.nets["baseline"]).elements
             if e[0][0].upper() in "RLC"]

    def net_of(start: rs.Net, x: np.ndarray) -> rs.Net:
        net = start.copy()
        for n, v in zip(names, x):
            value = net.get(n)[3]
            # a frequency-dependent value (an effect written in) keeps its shape, scaled
            net.set(n, (lambda f, g=value, k=np.exp(v): k * g(f)) if callable(value) else value * np.exp(v))
        return net

    def errors(start: rs.Net, x: np.ndarray) -> dict[str, np.ndarray]:
        model = _responses(net_of(start, x), case.kind, f)
        return {k: np.log(model[k] / truth[k]) for k in truth}

    def residuals(x: np.ndarray, start: rs.Net) -> np.ndarray:
        e = errors(start, x)
        r = np.concatenate([np.concatenate([v.real, v.imag]) / np.sqrt(2 * v.size) for v in e.values()])
        return np.where(np.isfinite(r), r, 1e3)

    big = float(np.log(100.0))
    hi = np.array([big if n.lower() in {x.lower() for x in free} else bound for n in names])
    best, noise = np.inf, 2 * case.noise ** 2
    zero = np.zeros(len(names))
    starts = [(home, zero)]
    if structure != "sections" and case.nets["baseline"].elements != case.nets["merged"].elements:
        starts.append((case.nets["baseline"], zero))
    # the truth's own constant values (as ratios to the merge, so the box stays the same), where the truth has the
    # baseline's structure (its effects left out)
    sections = case.nets.get("sections")
    if target == "truth" and structure != "sections" and sections is not None \
            and [e[0] for e in sections.elements if e[0][0].upper() in "RLC"] == names:
        starts.append((case.nets["merged"], np.array([np.log(sections.get(n)[3] / case.nets["merged"].get(n)[3])
                                                      for n in names])))
    rng = np.random.default_rng(7)
    starts += [(home, 0.4 * rng.standard_normal(len(names))) for _ in range(random_starts)]
    for start, x0 in starts:
        sol = least_squares(residuals, np.clip(x0, -0.999 * hi, 0.999 * hi), args=(start,), bounds=(-hi, hi),
                            max_nfev=max_nfev, x_scale="jac")
        e = errors(start, sol.x)
        best = min(best, max(float(np.mean(np.abs(v) ** 2)) for v in e.values()))
        if early and best <= noise:
            break
    return {"cost": best, "noise": noise, "detectable": bool(best > noise)}


#: A design case's box: values within twice the design tolerance (0.2) in log; beyond it a fit is drift.
DESIGN_BOUND = 2 * float(np.log(1.2))


def effects_shown(case, bound: float = DESIGN_BOUND, early: bool = True) -> dict[str, dict[str, float]]:
    """Does every hidden cause of a design case show above the noise? One :func:`best_baseline_fit` per cause.

    A missing section: the design's structure fitted to the truth's sections;
    a single effect: the design's structure fitted to the whole truth; an
    effect beside a missing section: the truth's sections fitted to the whole
    truth; each of two effects: the truth's sections with the other effect
    (its own form and parameters) fitted to the whole truth. Values within
    ``bound`` in log (twice the design tolerance), the drifted value free.

    Returns
    -------
    dict
        Cause -> :func:`best_baseline_fit`'s answer (``detectable``).
    """
    box = {"bound": bound, "free": tuple(case.truth.get("drift", ())), "early": early}
    causes = [c for c in case.causes if c != "none"]
    effects = [c for c in causes if c != "missing-section"]
    out: dict[str, dict[str, float]] = {}
    if "missing-section" in causes:
        out["missing-section"] = best_baseline_fit(case, **box)
        for c in effects:
            out[c] = best_baseline_fit(case, target="truth", structure="sections", **box)
    elif len(effects) == 1:
        out[effects[0]] = best_baseline_fit(case, target="truth", **box)
    else:
        for c in effects:
            other = next(x for x in effects if x != c)
            out[c] = best_baseline_fit(case, target="truth", structure="sections", keep=other, **box)
    return out
