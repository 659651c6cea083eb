"""A missing section sought as two whole sections that the baseline merged into one, seeded at the missing mode.

The split candidates of :mod:`.sections` start where the fitted baseline
ended (equal halves, couplings scaled to keep the common mode): a saddle of
the split model that local fits seldom leave. When the measurement shows a
resonance the fitted baseline does not produce (one section more is one
natural frequency more in the band), the search here starts elsewhere:

1. *From the nominal circuit.* The baseline as given (its values before
   fitting) is split, not the fitted one: a fit that had to absorb a missing
   mode distorts every value, the nominal design does not.
2. *Two whole sections.* Section ``j`` becomes two sections in series; the
   couplings of the new one follow the winding's coupling profile ``k(d)``,
   the mean coupling at each distance ``d`` in sections counted along the
   winding with one section more (extrapolated geometrically beyond the
   distances present). The old sections keep their couplings. A section that
   ends at ground gets a capacitor across its first half (the capacitor it
   had to ground is both its series and its end's shunt capacitance).
3. *Seeds with the symmetry broken.* The inductance is shared between the
   two in fractions ``a``, ``1 - a``, the series capacitance in ratios around
   equal, the new node's shunt capacitance over a grid around the winding's
   mean; both inductances are scaled so the winding's total (low-frequency)
   inductance stays the nominal one. The seeds are ranked by how well the
   resonances of their responses sit on the measured ones
   (:func:`resonance_score`), and by cost; the best few are fitted in full.

   A winding with a section the design lacks is also one section longer:
   sections on either side of the missing one are one section farther
   apart than the design counts them. The *respaced* split
   (``Unmerged(..., respaced=True)``) counts every distance along the
   lengthened winding: a coupling across the split (the first half's to the
   sections after it included) becomes ``k * p(d + 1) / p(d)``, with ``p``
   the winding's coupling profile over the design's distances, and the new
   section's couplings are ``p`` at its own distances. Its seeds keep the
   split section's own inductance (the halves and their mutual), not the
   winding's total, which the wider spacing lowers.
4. *Couplings.* The seeds are fitted with the couplings as designed; the
   best is then refitted with the couplings of the two sections free
   (:mod:`.sections`), while its fit with the designed couplings is the one
   merged back to refit the baseline (which keeps its couplings).

Whether any of this is tried is decided by :func:`missing_modes` (measured
resonances the fitted baseline lacks), so data without a missing mode cost
nothing extra.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from pris_cosim.circuits.circuit import GROUND, Circuit
from pris_cosim.errors import CircuitError
from pris_cosim.circuits.expressions import Expression

from estimation.resonances import find_resonances
from estimation.diagnosis.cores import shared_map
from estimation.diagnosis.causes.sections import (Chain, SectionCandidate, _make_pd, _unique, coupling_decay,
    coupling_matrix, find_chains, split_section, touched_couplings)

#: A measured resonance farther than this (relative frequency) from every model resonance counts as missing.
MODE_TOLERANCE = 0.04
#: Resonances smaller than this (dB) are not counted.
MIN_PROMINENCE_DB = 1.0
#: A measured point counts for resonances only if its stated standard deviation of ln H is under a third of
#: the prominence a resonance needs (noisier points make peaks and dips of their own).
MAX_RESONANCE_SD = MIN_PROMINENCE_DB * np.log(10) / 20 / 3


def resolved_points(uncertainty: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per response with a stated uncertainty: the points quiet enough to show resonances (``MAX_RESONANCE_SD``)."""
    return {n: np.asarray(s, float) <= MAX_RESONANCE_SD for n, s in uncertainty.items()}


def resonance_frequencies(f: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Resonance frequencies of ``h`` (Hz) and which are parallel (peaks of ``|h|``), at ``MIN_PROMINENCE_DB``."""
    r = find_resonances(f, h, min_prominence_db=MIN_PROMINENCE_DB)
    return np.array([x.frequency_hz for x in r]), np.array([x.kind == "parallel" for x in r], bool)


def missing_modes(f: np.ndarray, measured: Mapping[str, np.ndarray], predicted: Mapping[str, np.ndarray],
                  resolved: Mapping[str, np.ndarray] | None = None) -> int:
    """Measured impedance resonances (peaks and dips) that the model's responses do not reproduce.

    Parameters
    ----------
    f : numpy.ndarray, Hz
    measured, predicted : mapping
        Response name to complex values; only impedances (``Z...``) count.
    resolved : mapping, optional
        Response name to the points that count (:func:`resolved_points`); default all.

    Returns
    -------
    int
        Over the impedances, the largest excess of measured resonances of one
        kind over the model's, or of measured resonances with no model
        resonance of the same kind within :data:`MODE_TOLERANCE`.
    """
    worst = 0
    for a, b in _paired_resonances(f, measured, predicted, resolved):
        unmatched = sum(1 for x in a if not b.size or np.min(np.abs(b / x - 1)) > MODE_TOLERANCE)
        worst = max(worst, a.size - b.size, unmatched if a.size > b.size else 0)
    return worst


def _paired_resonances(f: np.ndarray, measured: Mapping[str, np.ndarray], predicted: Mapping[str, np.ndarray],
                       resolved: Mapping[str, np.ndarray] | None = None) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Per impedance (``Z...``) and kind (peak, dip): measured and model resonance frequencies, Hz (on the
    ``resolved`` points of each response only, when given)."""
    for name, h in measured.items():
        if not name.startswith("Z") or name not in predicted:
            continue
        keep = (resolved or {}).get(name)
        keep = np.ones(f.size, bool) if keep is None else keep
        if np.count_nonzero(keep) < 3:
            continue
        fm, pm = resonance_frequencies(f[keep], h[keep])
        fp, pp = resonance_frequencies(f[keep], predicted[name][keep])
        for kind in (True, False):
            yield fm[pm == kind], fp[pp == kind]


def resonance_score(f: np.ndarray, measured: Mapping[str, np.ndarray], predicted: Mapping[str, np.ndarray],
                    resolved: Mapping[str, np.ndarray] | None = None) -> float:
    """Distance between measured and model resonances (0: every one matched), summed over the impedances.

    Each measured resonance adds the log distance to the nearest model
    resonance of its kind, each model resonance half its distance to the
    nearest measured one; distances are capped at ``ln 1.5``. ``resolved``:
    as for :func:`missing_modes`.
    """
    cap = float(np.log(1.5))
    score = 0.0
    for a, b in _paired_resonances(f, measured, predicted, resolved):
        for x in a:
            score += min(cap, float(np.min(np.abs(np.log(b / x))))) if b.size else cap
        for x in b:
            score += 0.5 * (min(cap, float(np.min(np.abs(np.log(a / x))))) if a.size else cap)
    return score


def coupling_profile(circuit: Circuit, chain: Chain, values: Mapping[str, float], j: int
                     ) -> Callable[[int], float]:
    """``k(d)``: mean coupling of the chain's sections at distance ``d``, counted with section ``j`` split in two.

    Distances not present are extrapolated geometrically from the two
    largest present (ratio at most 1), or by the decay ``rho`` of
    :func:`.sections.coupling_decay` when fewer are known.
    """
    ks = coupling_matrix(circuit, values)
    ind = [x.lower() for x in chain.inductors]
    acc: dict[int, list[float]] = {}
    for a, b in itertools.combinations(range(len(ind)), 2):
        k = ks.get(frozenset((ind[a], ind[b])))
        if k is not None and k > 0:
            d = (b + (b > j)) - (a + (a > j))
            acc.setdefault(d, []).append(k)
    prof = {d: float(np.mean(v)) for d, v in acc.items()}
    rho = coupling_decay(circuit, [chain], values)
    known = sorted(prof)

    def k(d: int) -> float:
        if d in prof:
            return prof[d]
        below = [x for x in known if x < d]
        if below:
            d0 = below[-1]
            ratio = prof[d0] / prof[below[-2]] if len(below) > 1 else (rho or 0.5)
            return prof[d0] * min(ratio, 1.0) ** (d - d0)
        if known:
            return min(0.999, prof[known[0]] / (rho or 0.8) ** (known[0] - d))
        return rho ** d if rho > 0 else 0.0

    return k


def inductance_matrix(circuit: Circuit, names: Sequence[str]) -> np.ndarray:
    """Inductance matrix (H) of the named inductors, couplings included."""
    v = circuit.resolve(check=False)
    names = [n.lower() for n in names]
    L = np.array([float(v[n]) for n in names])
    M = np.diag(L)
    idx = {n: i for i, n in enumerate(names)}
    for e in circuit.of_kind("K"):
        a, b = (n.lower() for n in e.nodes)
        if a in idx and b in idx:
            M[idx[a], idx[b]] = M[idx[b], idx[a]] = float(v[e.key]) * np.sqrt(L[idx[a]] * L[idx[b]])
    return M


def _keep_total(M: np.ndarray, pair: np.ndarray, target: float) -> float:
    """Factor on the ``pair`` inductances that makes the sum of ``M`` equal ``target`` (1 when impossible)."""
    A = M[~pair][:, ~pair].sum()
    B = 2 * M[pair][:, ~pair].sum()
    C = M[pair][:, pair].sum()
    disc = B * B - 4 * C * (A - target)
    if C <= 0 or disc < 0:
        return 1.0
    u = (-B + np.sqrt(disc)) / (2 * C)
    return float(u * u) if u > 0 else 1.0


class Unmerged:
    """Section ``j`` of ``chain`` in ``circuit`` made two whole sections.

    With ``respaced`` every coupling is counted along the winding made one
    section longer (the module's docstring, step 2).

    Attributes
    ----------
    candidate : SectionCandidate
    first, second : dict
        Element names (``L``, ``R``, ``C``) of the two sections.
    shunt : str or None
        The new node's capacitor to ground.
    inductors : list of str
        The chain's inductors after the split.
    total_h : float, H
        The chain's total inductance before the split (kept by the seeds).
    """

    def __init__(self, circuit: Circuit, chain: Chain, j: int, respaced: bool = False):
        values = circuit.resolve(check=False)
        k = coupling_profile(circuit, chain, values, j)
        # respaced: the profile over the design's own distances, and every distance counted with the split in
        p = coupling_profile(circuit, chain, values, len(chain.sections)) if respaced else k
        k_in = float(min(p(1), 0.999))
        sec = chain.sections[j]
        base = split_section(circuit, chain, j, coupling_decay(circuit, [chain], values), 1.0)
        c = base.circuit
        old_l = sec.inductor.lower()
        new = list(base.new_elements)
        new_l = next(n for n in new if n[0].upper() == "L").lower()
        pos = {name.lower(): m + (m > j) for m, name in enumerate(chain.inductors)}
        pos[new_l] = j + 1
        ks = coupling_matrix(circuit, values)
        over: dict[str, float] = {}
        new_k = []
        for e in c.of_kind("K"):
            if isinstance(e.value, Expression):
                continue
            pair = [n.lower() for n in e.nodes]
            if old_l in pair and new_l in pair:
                over[e.name] = k_in
                new_k.append(e.name)
            elif new_l in pair:
                other = next(n for n in pair if n != new_l)
                over[e.name] = p(abs(pos[other] - pos[new_l])) if other in pos else \
                    ks.get(frozenset((old_l, other)), float(e.value))
                new_k.append(e.name)
            elif old_l in pair:
                other = next(n for n in pair if n != old_l)
                over[e.name] = ks.get(frozenset((old_l, other)), float(e.value))
            if respaced and pair[0] in pos and pair[1] in pos and new_l not in pair:
                a, b = sorted(pos[n] - (pos[n] > j) for n in pair)  # the design's positions
                if a <= j < b and p(b - a) > 0:
                    over[e.name] = float(ks.get(frozenset(pair), float(e.value))) * min(1.0, p(b - a + 1) / p(b - a))
        L = float(values[old_l])
        half = L / (2 * (1 + k_in))
        over[sec.inductor] = half
        over[new_l] = half
        c = c.with_values(over)
        shunt = next((n for n in new if n.upper().startswith("CG")), None)
        series = [float(values[n.lower()]) for s in chain.sections for n in s.series_caps]
        first_c = sec.series_caps[0] if sec.series_caps else None
        if first_c is None and series and shunt is not None and sec.end == GROUND:
            mid = next(n for n in c.element(shunt).nodes if n != GROUND)
            first_c = c.add(_unique(c, "Cs_split"), sec.start, mid, float(np.mean(series))).name
            new.append(first_c)
        c = _make_pd(c, new_k)
        how = f"section {j + 1} of the winding at {chain.port} is two sections" + (
            ", the winding one section longer" if respaced else "")
        self.candidate = SectionCandidate(c, how, new, chain.port, touched_couplings(c, [sec.inductor, new_l]))
        self.k_name = next((e.name for e in c.of_kind("K") if {n.lower() for n in e.nodes} == {old_l, new_l}), None)
        self.first = {"L": sec.inductor, "R": sec.resistor, "C": first_c}
        self.second = {"L": next(n for n in new if n[0].upper() == "L"),
                       "R": next((n for n in new if n[0].upper() == "R"), None),
                       "C": next((n for n in new if n.upper().startswith("C") and n != shunt
                                  and not n.upper().startswith("CS_SPLIT")), None)}
        self.shunt = shunt
        self.k_in = k_in
        self._start = sec.start
        self.own_c = sec.series_caps[0] if sec.series_caps else None
        self.inductors = list(chain.inductors) + [self.second["L"]]
        self.respaced = respaced
        # the seeds keep the winding's total inductance; respaced, the split section's own (the total as built)
        self.total_h = float(inductance_matrix(c if respaced else circuit,
                                               self.inductors if respaced else chain.inductors).sum())

    def own_elements(self) -> list[str]:
        """Names of the two sections' own elements: inductors, resistors, series capacitors and the new node's
        capacitor to ground (what the split shares between them, not anchored to the design)."""
        return [n for n in (*self.first.values(), *self.second.values(), self.shunt) if n]

    def merged_back(self, fitted: Circuit) -> dict[str, float]:
        """Values of the split section's own elements with the two fitted sections merged into one again.

        Inductances add with their mutual, resistances add, series
        capacitances combine in series (a capacitor added across the first
        half of a section ending at ground joins its capacitor to ground in
        series with the new node's).
        """
        v = fitted.resolve(check=False)
        get = lambda n: float(v[n.lower()])  # noqa: E731
        l1, l2 = get(self.first["L"]), get(self.second["L"])
        k_in = get(self.k_name) if self.k_name else self.k_in  # the fitted coupling between the two halves
        out = {self.first["L"]: l1 + l2 + 2 * k_in * np.sqrt(l1 * l2)}
        if self.first["R"] and self.second["R"]:
            out[self.first["R"]] = get(self.first["R"]) + get(self.second["R"])
        if self.own_c and self.second["C"]:
            c1, c2 = get(self.own_c), get(self.second["C"])
            out[self.own_c] = c1 * c2 / (c1 + c2)
        elif self.first["C"] and self.shunt and self.first["C"] != self.own_c:
            ground = [e.name for e in fitted.of_kind("C") if set(e.nodes) == {self._start, GROUND}]
            if ground:
                c1, c2 = get(self.first["C"]), get(self.shunt)
                out[ground[0]] = get(ground[0]) + c1 * c2 / (c1 + c2)
        return out

    def seeds(self, free: Sequence[str], tail: np.ndarray, fractions: Sequence[float] = (0.35, 0.5, 0.65),
              cap_ratios: Sequence[float] = (0.5, 2.0), shunts: Sequence[float] = (0.3, 1.0, 3.0)) -> np.ndarray:
        """Start vectors (log ratios to the candidate's values over ``free``, then ``tail``), one per seed."""
        c = self.candidate.circuit
        v = c.resolve(check=False)
        col = {n.lower(): i for i, n in enumerate(free)}
        names = [n.lower() for n in self.inductors]
        pair = np.array([n in (self.first["L"].lower(), self.second["L"].lower()) for n in names])
        has_c = self.first["C"] is not None and self.second["C"] is not None
        rows = []
        # first the plain split (equal halves, equal capacitances, the shunt as built): the seed of a design whose
        # merged section was two alike
        plain = [(0.5, 1.0, 1.0)]
        for a, cr, cg in plain + [p for p in itertools.product(fractions, cap_ratios if has_c else (1.0,),
                                                                shunts if self.shunt else (1.0,)) if p not in plain]:
            x = np.zeros(len(free))
            l1, l2 = float(v[self.first["L"].lower()]) * 2 * a, float(v[self.second["L"].lower()]) * 2 * (1 - a)
            M = inductance_matrix(c.with_values({self.first["L"]: l1, self.second["L"]: l2}), names)
            s = _keep_total(M, pair, self.total_h)
            steps = {self.first["L"]: np.log(2 * a * s), self.second["L"]: np.log(2 * (1 - a) * s)}
            if self.first["R"] and self.second["R"]:
                steps.update({self.first["R"]: np.log(2 * a), self.second["R"]: np.log(2 * (1 - a))})
            if has_c:  # the two in series keep the section's series capacitance
                steps.update({self.first["C"]: np.log((1 + cr) / 2), self.second["C"]: np.log((1 + 1 / cr) / 2)})
            if self.shunt:
                steps[self.shunt] = np.log(cg)
            if self.first["C"] and self.first["C"] != self.own_c and self.shunt:
                # a section that ended at ground: the capacitance added across its first half, in series with the
                # new node's, was part of the start node's capacitance to ground (the inverse of merged_back)
                ground = [e.name for e in c.of_kind("C") if set(e.nodes) == {self._start, GROUND}]
                total = sum(float(v[n.lower()]) for n in ground)
                c1, c2 = float(v[self.first["C"].lower()]), float(v[self.shunt.lower()]) * cg
                if total > 0:
                    for n in ground:
                        steps[n] = np.log(max(1 - c1 * c2 / (c1 + c2) / total, 0.1))
            for name, step in steps.items():
                if name.lower() in col:
                    x[col[name.lower()]] = step
            rows.append(np.concatenate([x, tail]))
        return np.array(rows)


def unmerged_candidates(nominal: Circuit, ports: Sequence[str]) -> list[Unmerged]:
    """Every section of every chain of the nominal circuit made two whole sections."""
    out = []
    for ch in find_chains(nominal, ports):
        for j in range(len(ch.sections)):
            try:
                out.append(Unmerged(nominal, ch, j))
            except (ValueError, KeyError, StopIteration, CircuitError, np.linalg.LinAlgError):
                continue
    return out


def search_unmerged(make_fit: Callable, f: np.ndarray, measured: Mapping[str, np.ndarray], nominal: Circuit,
                    ports: Sequence[str], tail: np.ndarray, by_resonance: int = 2, by_cost: int = 0,
                    screen_nfev: int = 15, max_nfev: int = 80, coupling_nfev: int = 60, free_couplings: bool = True,
                    resolved: Mapping[str, np.ndarray] | None = None, all_seeds: bool = True, seed_nfev: int = 8,
                    schedules: Sequence[Sequence[float]] | None = None, good_enough: float = 0.0):
    """Fit every un-merged candidate from its best seeds; the best fit, its candidate and the fit to merge back.

    The seeds are fitted with the couplings as designed (the baseline's
    own: the fit whose two sections merged back refit the baseline), the
    best of them then with the couplings the split touches free too.

    Parameters
    ----------
    make_fit : callable
        ``make_fit(circuit, couplings)`` gives the :class:`.fit.FrequencyFit` of a
        candidate circuit with those couplings free (with the effects already
        named, whose fitted parameters are ``tail``).
    f : numpy.ndarray, Hz
    measured : mapping
        Response name to complex values.
    nominal : Circuit
        The baseline as given (values before fitting).
    ports : sequence of str
    tail : numpy.ndarray
        Parameters of the effects already named (empty for none).
    by_resonance, by_cost : int
        Seeds fitted per candidate: the best by :func:`resonance_score`, then
        the best by cost among the rest.
    screen_nfev, max_nfev, coupling_nfev : int
        Evaluations of the short fits of every seed kept, of the final fit
        of the best, and of its fit with the couplings free.
    all_seeds : bool
        Also fit every seed continued through smoothed errors from a decade
        down (:meth:`.fit.FrequencyFit.fit_continued`, ``seed_nfev``
        evaluations per stage), the prior out of the smoothed stages; the
        best of those gets its final fit too, and the better of the two
        final fits is returned.
    schedules : sequence of sequences of float, optional
        Smoothing schedules (decades) of those fits, tried in turn until a
        seed's objective reaches ``good_enough`` (default: one,
        :data:`.fit.WIDE_CONTINUATION`).
    free_couplings : bool
        Refit the best with the couplings the split touches free.
    resolved : mapping, optional
        Points that count for resonances, by response (:func:`resolved_points`).

    Returns
    -------
    tuple or None
        ``(fit, candidate, merged)``: the best fit (couplings free), its
        :class:`Unmerged` and the fit with the couplings as designed.
    """
    from estimation.diagnosis.fit import WIDE_CONTINUATION, DiagnosisError

    continued: list[tuple] = []
    schedules = list(schedules or [WIDE_CONTINUATION])
    fits, jobs = [], []
    for um in unmerged_candidates(nominal, ports):
        try:
            fit = make_fit(um.candidate.circuit, ())
            rows = um.seeds(fit.free, tail)
            pred = fit.predict_batch(rows)
            r = fit.residuals_batch(rows)
        except (DiagnosisError, ValueError, CircuitError, np.linalg.LinAlgError):
            continue
        cost = np.sum(r * r, axis=1)
        score = np.array([resonance_score(f, measured, {k: v[i] for k, v in pred.items()}, resolved)
                          for i in range(len(rows))])
        pick = list(np.lexsort((cost, score))[:by_resonance])
        pick += [i for i in np.argsort(cost) if i not in pick][:by_cost]
        pick += [] if 0 in pick else [0]  # the plain split (:meth:`Unmerged.seeds`' first) is always fitted
        jobs += [(um, fit, rows[i]) for i in pick]
        fits.append((um, fit, rows))
    # the short fits of the picked seeds, shared with the helper process (:mod:`.cores`)
    done = shared_map(_seed_fitted, [(fit, row, {"max_nfev": screen_nfev}) for _, fit, row in jobs])
    screened = [(res.cost, um, fit, res) for (um, fit, _), res in zip(jobs, done) if res is not None]
    for stages in schedules if all_seeds else []:
        # every seed continued through smoothed errors (the seeds' resonances are tens of per cent off the
        # measured): which seed leads to the measured resonances shows only once it is fitted
        jobs = [(um, fit, row) for um, fit, rows in fits for row in rows]
        done = shared_map(_seed_fitted, [(fit, row, {"stages": stages, "seed_nfev": seed_nfev})
                                         for _, fit, row in jobs])
        for um, fit, _ in fits:
            fitted = [(res.cost, um, fit, res) for (u, _, _), res in zip(jobs, done) if u is um and res is not None]
            continued += sorted(fitted, key=lambda t: t[0])[:by_resonance + by_cost]
        if continued and min(t[3].objective for t in continued) <= good_enough:
            break
    found = [_finish(min(group, key=lambda t: t[0]), make_fit, max_nfev, coupling_nfev, free_couplings)
             for group in (screened, continued) if group]
    return min(found, key=lambda t: t[0].bic) if found else None


def _seed_fitted(args: tuple[Any, np.ndarray, dict[str, Any]]) -> Any:
    """A seed's local fit (:func:`search_unmerged`): ``(fit, seed, options)`` to the fit result, or None when the
    network degenerates. With ``stages`` in the options it is continued through smoothed errors
    (:meth:`.fit.FrequencyFit.fit_continued`, the prior out of the smoothed stages), else a short plain fit."""
    from estimation.diagnosis.fit import DiagnosisError

    fit, row, opts = args
    try:
        if "stages" in opts:
            return fit.fit_continued(row, stages=opts["stages"], stage_nfev=opts["seed_nfev"],
                                     max_nfev=opts["seed_nfev"], tol=1e-6, prior_in_stages=False)
        return fit.fit(x0s=row[None], grid=False, max_nfev=opts["max_nfev"], tol=1e-6)
    except (DiagnosisError, ValueError, CircuitError, np.linalg.LinAlgError):
        return None


def _finish(best: tuple, make_fit: Callable, max_nfev: int, coupling_nfev: int, free_couplings: bool) -> tuple:
    """The final fit of a screened seed, then with the couplings the split touches free: (fit, candidate, merged)."""
    from estimation.diagnosis.fit import DiagnosisError

    _, um, fit, first = best
    try:
        res = fit.fit(x0s=first.x[None], grid=False, max_nfev=max_nfev, tol=1e-7)
    except (DiagnosisError, ValueError, CircuitError, np.linalg.LinAlgError):
        res = first
    res = res if res.cost < first.cost else first
    merged = res
    if free_couplings and um.candidate.couplings:  # then the couplings the split touches, from there
        try:
            loose = make_fit(res.fitted_circuit(), um.candidate.couplings)
            nc = res.x.size - sum(len(e.parameters) for e in res.effects)
            x0 = np.concatenate([np.zeros(loose.nc), res.x[nc:]])
            refined = loose.fit(x0s=x0[None], grid=False, max_nfev=coupling_nfev, tol=1e-7)
            if refined.objective < res.objective:
                res = refined
        except (DiagnosisError, ValueError, CircuitError, np.linalg.LinAlgError):
            pass
    return res, um, merged
