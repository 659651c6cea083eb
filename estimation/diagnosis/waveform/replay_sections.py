"""The replay's structural cause: a missing section of the winding, fitted exactly to the record.

A winding whose design merged two sections into one (or left one out at an
end) has one natural frequency more than the design: no effect of the
catalogue adds it. The candidates are the frequency path's
(:mod:`.causes.unmerge`, :mod:`.causes.sections`), built from the design
circuit (the fitted baseline has absorbed the missing mode into distorted
values; the design has not):

* every section of every chain made two whole sections
  (:class:`.unmerge.Unmerged`: the inductance shared with the coupling
  profile of the winding, the series capacitance split in two in series,
  the new node with its own capacitance to ground);
* a section added at the port end and at the far end
  (:func:`.sections.add_section`, inductance scales ``ADD_SCALES``).

Each structure is a new :class:`.joint_fit.ReplayProblem` on its circuit,
the source and the causes already named included: the split section's
values, the new elements and the couplings of the changed inductors (both
halves of a split, or the added one, and the tight couplings the change
touches) carry no prior (the design says nothing of them;
:meth:`.prior.DesignPrior.anchored`), every other value keeps its prior. So
they count as parameters ``k`` of the replay's BIC (:func:`.replay._significant`):
a structure pays ``ln N`` per value it frees, which is what the frequency
path's held-out check guards against; no further check is applied.

Cost
    Every structure is *screened*: its seeds (:meth:`.Unmerged.seeds`: the
    inductance shared unequally, the series capacitances in ratio, the new
    node's capacitance over a grid; for an added section its inductance
    scales), set on the values of the current fit and on the design values,
    are costed in one batch, and the best gets a short fit
    (``SCREEN_NFEV`` evaluations). The best ``REFINE`` structures are then
    fitted in full (``SECTION_NFEV`` evaluations, started afresh from where
    the last fit ended while that lowers the objective by ``RESTART_GAIN``:
    a trust region shrunk on a degenerate network stops early).

Why the exact replay screens (and not the H1 of ``v_in / i_in``)
    The record's spectra are exact for the replay, while the ratio of the
    sampled ``v_in`` and ``i_in`` is the winding's impedance only below a
    tenth of the sampling rate and where the PRBS excites well, and its
    noise hides the resonances the frequency path ranks splits by (a record
    of 12,600 samples at 0.2 % noise: 147 of its 620 bins quiet enough to
    show one, :func:`.unmerge.resolved_points`, and one resonance seen where
    the replay's misfit is 238 times the noise). The short fits in the
    replay cost a few seconds per record, and rank the structures on the
    objective that names them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pris_cosim.circuits.circuit import Circuit
from pris_cosim.circuits.expressions import Expression

from estimation.diagnosis.causes.sections import add_section, coupling_decay, find_chains
from estimation.diagnosis.causes.unmerge import unmerged_candidates
from estimation.diagnosis.fit import CANDIDATE_FAILURES
from estimation.diagnosis.waveform.joint_fit import Part, ReplayFit, ReplayProblem

#: The cause a structure names.
CAUSE = "missing-section"
#: Inductance scales of a section added at an end (its series capacitance scaled by the inverse).
ADD_SCALES = (0.3, 1.0, 3.0)
#: Evaluations of the short fit screening each structure.
SCREEN_NFEV = 5
#: Structures fitted in full after the screen, and the evaluations of each run of that fit.
REFINE = 2
SECTION_NFEV = 40
#: Fresh starts of the full fit from where the last ended, while one lowers the objective by ``RESTART_GAIN``.
RESTARTS = 10
RESTART_GAIN = 0.01


@dataclass
class Structure:
    """A winding with one section more, its seeds and the couplings of its new inductor.

    Attributes
    ----------
    circuit : Circuit
        The winding with the section (values as built).
    how : str
        What the structure is, e.g. "section 2 of the winding at n1 is two sections".
    seeds : callable
        ``seeds(free)``: start rows (log ratios to ``circuit``'s values over the names ``free``).
    couplings : tuple of str
        K elements of the new inductor (and tight couplings the change touches), freed in the refinement.
    """

    circuit: Circuit
    how: str
    seeds: Callable[[list[str]], np.ndarray] = field(repr=False)
    couplings: tuple[str, ...] = ()


def _numeric(circuit: Circuit, names: list[str]) -> Circuit:
    """``circuit`` with the named elements' expression values replaced by their numbers (a structure's own
    values are fitted one by one, not through the design's shared parameters)."""
    vals = circuit.resolve(check=False)
    over = {n: float(vals[n.lower()]) for n in names
            if n and circuit.has_element(n) and isinstance(circuit.element(n).value, Expression)}
    return circuit.with_values(over) if over else circuit


def _new_couplings(circuit: Circuit, inductors: list[str], tight: list[str]) -> tuple[str, ...]:
    """The numeric K elements of ``inductors`` (the new section's, or the two halves of a split one), then the
    tight couplings the change touches."""
    own = {n.lower() for n in inductors}
    ks = [k.name for k in circuit.of_kind("K") if not isinstance(k.value, Expression)
          and own & {n.lower() for n in k.nodes}]
    return tuple(dict.fromkeys(ks + list(tight)))


def section_structures(circuit: Circuit, port: str) -> list[Structure]:
    """Every split of a section and every end addition of every chain of ``circuit`` at ``port``."""
    out: list[Structure] = []
    for um in unmerged_candidates(circuit, [port]):
        own = [um.first["L"], um.first["C"], um.second["L"], um.second["C"], um.shunt]
        c = _numeric(um.candidate.circuit, [n for n in own if n])
        um.candidate.circuit = c
        out.append(Structure(c, um.candidate.how, lambda free, um=um: um.seeds(free, np.zeros(0)),
                             _new_couplings(c, [um.first["L"], um.second["L"]], list(um.candidate.couplings))))
    chains = find_chains(circuit, [port])
    rho = coupling_decay(circuit, chains, circuit.resolve(check=False))
    for ch in chains:
        for at in ("port", "end"):
            try:
                grid = [add_section(circuit, ch, at, rho, l_scale=g, c_scale=1.0 / g) for g in ADD_SCALES]
            except CANDIDATE_FAILURES + (KeyError, StopIteration):
                continue
            main = grid[ADD_SCALES.index(1.0)]
            new_l = next(n for n in main.new_elements if n[0].upper() == "L")
            out.append(Structure(main.circuit, main.how,
                                 lambda free, grid=grid, main=main: _grid_rows(free, grid, main),
                                 _new_couplings(main.circuit, [new_l], list(main.couplings))))
    return out


def _grid_rows(free: list[str], grid: list[Any], main: Any) -> np.ndarray:
    """Start rows of an added section: its new elements' values at each scale, relative to ``main``'s."""
    ref = main.circuit.resolve(check=False)
    rows = []
    for cand in grid:
        v = cand.circuit.resolve(check=False)
        rows.append([math.log(float(v[n.lower()]) / float(ref[n.lower()])) if n in main.new_elements
                     and n.lower() in v and float(ref[n.lower()]) > 0 else 0.0 for n in free])
    return np.array(rows, float)


def scaled_bic(reference: ReplayFit, fit: ReplayFit) -> float:
    """``chi^2 / s^2 + k ln N`` of ``fit`` with the noise scale ``s^2 = max(1, chi^2 / N)`` of ``reference``
    (the criterion of :func:`.replay._significant`)."""
    s2 = max(1.0, reference.rss / reference.n_residuals)
    return fit.objective / s2 + fit.n_params * math.log(reference.n_residuals)


def _starts(prob: ReplayProblem, current: ReplayFit, st: Structure) -> list[np.ndarray]:
    """The structure's seeds, its own values set on the current fit's values and on the design's."""
    given: dict[tuple[str, str], float] = {}
    labels = [p.effect.label for p in current.parts if p.effect is not None]
    for lab, vals in zip(labels, current.extra):
        given.update({(lab, k): v for k, v in vals.items()})
    kept = {k: v for k, v in current.winding.items() if k in prob.held and k in current.held}
    bases = [prob.vector(current.source, kept, [given]), prob.vector(current.source, None, [given])]
    free = list(prob.ff.free)
    rows = st.seeds(free)
    own = np.array([n.lower() not in prob.held for n in free], bool)
    cols = prob.n_src + np.flatnonzero(own)
    lo, hi = prob.bounds()
    out = []
    for base in bases:
        for row in rows:
            th = base.copy()
            th[cols] = np.asarray(row)[own]
            out.append(np.clip(th, lo + 1e-9, hi - 1e-9))
    return out


def _problem(make: Callable[[list[Part]], ReplayProblem], current: ReplayFit, st: Structure,
             couplings: tuple[str, ...] = ()) -> tuple[ReplayProblem, Part]:
    part = Part(CAUSE, circuit=st.circuit, how=st.how, couplings=couplings)
    return make([p for p in current.parts if p.circuit is None] + [part]), part


def _finished(prob: ReplayProblem, part: Part, fit: ReplayFit) -> ReplayFit:
    """``fit`` with its structural part holding the fitted couplings in its circuit and its own values."""
    over = {n: fit.winding[n.lower()] for n in part.couplings if n.lower() in fit.winding}
    own = {k: v for k, v in fit.winding.items() if k not in prob.held and k not in {n.lower() for n in part.couplings}}
    done = Part(CAUSE, circuit=part.circuit.with_values(over) if over else part.circuit, how=part.how,
                values=own)
    fit.parts = [p if p is not part else done for p in fit.parts]
    return fit


def best_section(make: Callable[[list[Part]], ReplayProblem], current: ReplayFit, structures: list[Structure],
                 log: Callable[[str], None] = lambda m: None) -> ReplayFit | None:
    """The best structure added to ``current`` (its causes kept): every one screened, the best refined.

    Parameters
    ----------
    make : callable
        Parts to the :class:`.joint_fit.ReplayProblem` of the record.
    current : ReplayFit
        The fit the section is added to (without a structure).
    structures : list of Structure
        :func:`section_structures` of the design.
    log : callable
        Progress lines.

    Returns
    -------
    ReplayFit or None
        The best fit (lowest :func:`scaled_bic` against ``current``), None when no structure can be fitted.
    """
    t0 = time.perf_counter()
    screened = []
    for st in structures:
        try:
            prob, part = _problem(make, current, st, st.couplings)
            r = prob.fit(_starts(prob, current, st), max_nfev=SCREEN_NFEV, screen=1)
        except CANDIDATE_FAILURES:
            continue
        screened.append((r.objective, st, prob, part, r))
    if not screened:
        return None
    screened.sort(key=lambda t: t[0])
    best = None
    for _, st, prob, part, first in screened[:REFINE]:
        try:
            r = first
            for _ in range(RESTARTS):  # a trust region shrunk on a degenerate network: started afresh
                again = prob.fit([r.theta], max_nfev=SECTION_NFEV, screen=1)
                done = again.objective > (1 - RESTART_GAIN) * r.objective
                r = again if again.objective < r.objective else r
                if done:
                    break
            r = _finished(prob, part, r)
        except CANDIDATE_FAILURES:
            continue
        log(f"  {st.how}: chi2/N {first.rss / first.n_residuals:.4g} screened, {r.rss / r.n_residuals:.4g} "
            f"refined ({r.nfev} evaluations, {r.n_params} parameters)")
        if best is None or scaled_bic(current, r) < scaled_bic(current, best):
            best = r
    if best is not None:
        best.wall_s = time.perf_counter() - t0
        log(f"{CAUSE}: {best.structure} best of {len(screened)} structures "
            f"({', '.join(f'{t[1].how}: {t[0]:.4g}' for t in screened[:REFINE])})")
    return best
