"""The fingerprint model: an N-section winding fitted to the healthy sweep.

The sections are equal (:class:`_Packer`): the same core inductance, series
capacitance and ground capacitance, with separate ground capacitances at the
two end nodes (leads and fixture) and the port shunts of the set-up.  A
winding of uniform construction is what the section index has to mean for a
fault's location: in a model whose sections were fitted freely (tried
before) the per-section inductances spread over a factor of 25 and a
section's index said nothing about where along the winding it lies.  A
linear grading of the section parameters was tried as well: at ``N = 8`` it
came back to equal sections, at ``N = 6`` it ran to a grading of 150 to 1
in inductance.  The uniform model fits the shared reference with a
weighted rms about twice that of the free one, which the fault fits do not
see (they fit changes; see :mod:`estimation.diagnosis.sfra.faults`).

The reference sweep's ``Y11``, ``Y21`` and ``Y22`` are fitted jointly by the
winding of :mod:`estimation.diagnosis.sfra.winding`, with complex log residuals
``ln(Y_model / Y_measured)`` (real part: log-magnitude, imaginary part: phase
in rad) divided by the noise estimated from the data itself
(:func:`estimation.diagnosis.sfra.sweep.estimate_noise`) combined with a model-error
floor.  Above about 100 kHz ``S21`` nears the analyser's noise floor; the
estimated noise grows there and the weights fall with it, without any fixed
band limit.

The section count ``N`` comes from the data: the resonances of the
end-to-end response are counted (peaks of ``|Y21|`` and of ``|1/Y21|``
where the data stand above their noise); a section adds about one series
and one anti-resonance, so ``N0 = ceil(count / 2) + 1``; ``N0 - 1`` to
``N0 + 2`` are fitted (each from :data:`STARTS` starting points and from
the ``N - 1`` fit redivided, as the ladder fit has local minima), then
``N + 1`` as long as one of the last :data:`PATIENCE` counts tried has the
lowest BIC (up to :data:`MAX_SECTIONS`; a single count can end in a local
minimum); the lowest BIC wins.  The parameter count does not grow with
``N``, and on the shared reference the misfit falls with every section
added up to :data:`MAX_SECTIONS`.

Fits run by continuation in frequency (fit below 2 kHz, then up to 20 kHz,
100 kHz and the whole sweep), which keeps the resonances from trapping the
optimiser.  The result is cached per reference file (key: file content hash
+ :data:`CODE_VERSION`), in ``$PRIS_COSIM_CACHE`` or ``~/.cache/pris-cosim``
unless a directory is given.
"""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import find_peaks
from threadpoolctl import threadpool_limits

from estimation.diagnosis.fit import DiagnosisError, bic

from estimation.diagnosis.sfra.sweep import MODEL_FLOOR, Sweep
from estimation.diagnosis.sfra.winding import WindingModel, admittance

__all__ = ["Fingerprint", "fit_fingerprint", "load_or_fit", "count_resonances", "model_y", "cache_dir",
           "CODE_VERSION"]

#: Part of the cache key: bump when the model or the fit changes.
CODE_VERSION = "sfra-fingerprint-4"

#: Largest section count the automatic search goes to.
MAX_SECTIONS = 10

#: The search goes on while the best count is less than this many below the largest tried.
PATIENCE = 2

#: Continuation bands of the reference fit, Hz.
BANDS_HZ = (2e3, 2e4, 1e5, np.inf)

#: Relative noise above which the end-to-end response is not used to count resonances.
CLEAN_NOISE = 0.03

#: Starting points of each fit: factors on the series and ground capacitances of the uniform start.
STARTS = ((1.0, 1.0), (0.5, 2.0), (2.0, 0.5))

#: Every ``DECIMATE``-th point is fitted (log-spaced sweeps of ~200 points per decade).
DECIMATE = 3


def model_y(model: WindingModel, f: np.ndarray) -> np.ndarray:
    """``Y11, Y21, Y22`` of a model, S, shape ``(F, 3)``."""
    y = admittance(model, f)
    return np.stack([y[:, 0, 0], y[:, 1, 0], y[:, 1, 1]], axis=1)


def weights(sweep: Sweep) -> np.ndarray:
    """Residual standard deviation per point and response: noise and model floor, shape ``(F, 3)``."""
    return np.sqrt(sweep.noise**2 + MODEL_FLOOR**2)


def log_residuals(model_values: np.ndarray, data: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Real residual vector ``[Re, Im] of ln(model / data) / sigma``."""
    with np.errstate(all="ignore"):
        r = np.log(model_values / data) / sigma
    out = np.concatenate([r.real.ravel(), r.imag.ravel()])
    return np.where(np.isfinite(out), out, 1e6)


def count_resonances(sweep: Sweep) -> int:
    """Resonances of the end-to-end response that stand above the noise.

    Counted from the lowest frequency up to where the estimated noise of
    ``Y21`` first exceeds :data:`CLEAN_NOISE` (above, the analyser's noise
    floor makes ripples that are not resonances of the winding).

    Peaks of ``ln|Y21|`` (series resonances) and of ``-ln|Y21|``
    (anti-resonances) with a prominence of at least 0.5 (about 4 dB) and of
    five times the local noise level.
    """
    noise = sweep.noise[:, 1]
    noisy = np.flatnonzero(noise > CLEAN_NOISE)
    end = int(noisy[0]) if noisy.size else noise.size
    ly = np.log(np.abs(sweep.y[:end, 1]))
    noise = noise[:end]
    n = 0
    for sign in (1.0, -1.0):
        peaks, props = find_peaks(sign * ly, prominence=0.5)
        ok = props["prominences"] > 5.0 * noise[peaks]
        n += int(np.count_nonzero(ok))
    return n


class _Packer:
    """Map a uniform winding to/from a vector of (mostly log) parameters with bounds.

    The ``N`` sections are equal (the same turns, hence the same core
    inductance, series capacitance and ground capacitance of the interior
    nodes): the section index is then a position along the winding, which is
    what locates a fault.  The two end nodes have their own ground
    capacitances (leads and fixture).  :data:`N_PARAMS` parameters whatever ``N``.
    """

    def __init__(self, n: int):
        self.n = n

    def pack(self, m: WindingModel) -> np.ndarray:
        cg_in = m.Cg[1:-1] if m.n > 1 else m.Cg[:1]
        return np.array([np.log(np.mean(m.L)), np.log(np.mean(m.Cs)), np.log(np.mean(cg_in)), np.log(m.Cg[0]),
                         np.log(m.Cg[-1]), np.log(1.0 - m.rho), np.log(m.r_dc), m.beta, np.log(m.tan_c),
                         np.log(m.f_eddy), m.g1 * 1e5, m.b1 * 1e5, m.g2 * 1e5, m.b2 * 1e5])

    def unpack(self, x: np.ndarray) -> WindingModel:
        n = self.n
        cg = np.full(n + 1, np.exp(x[2]))
        cg[0], cg[-1] = np.exp(x[3]), np.exp(x[4])
        return WindingModel(L=np.full(n, np.exp(x[0])), Cs=np.full(n, np.exp(x[1])), Cg=cg,
                            rho=float(1.0 - np.exp(x[5])), r_dc=float(np.exp(x[6])), beta=float(x[7]),
                            tan_c=float(np.exp(x[8])), f_eddy=float(np.exp(x[9])),
                            g1=float(x[10] * 1e-5), b1=float(x[11] * 1e-5),
                            g2=float(x[12] * 1e-5), b2=float(x[13] * 1e-5))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = np.array([np.log(1e-3), np.log(1e-13), np.log(1e-14), np.log(1e-14), np.log(1e-14),
                       np.log(1e-5), np.log(1.0), 0.0, np.log(1e-5), np.log(10.0), -100, -100, -100, -100])
        hi = np.array([np.log(1e2), np.log(1e-7), np.log(1e-7), np.log(1e-7), np.log(1e-7),
                       np.log(0.7), np.log(1e4), 0.3, np.log(0.5), np.log(1e7), 100, 100, 100, 100])
        return lo, hi


#: Fitted parameters of the reference model (see :class:`_Packer`).
N_PARAMS = 14


def _start(sweep: Sweep, n: int) -> WindingModel:
    """Uniform starting winding from the low-frequency inductance and the first anti-resonance."""
    f = sweep.frequency_hz
    z = sweep.z_end_to_end
    lf = int(np.argmin(np.abs(f - 100.0)))
    l_tot = float(np.imag(z[lf]) / (2 * np.pi * f[lf])) if np.imag(z[lf]) > 0 else 1.0
    l_tot = max(l_tot, 1e-6)
    r_dc = max(float(np.real(z[0])) * 0.5, 0.1)
    band = f < 1e5
    fa = float(f[band][np.argmax(np.abs(z[band]))]) if np.any(band) else float(f[len(f) // 2])
    c_eff = 1.0 / ((2 * np.pi * fa) ** 2 * l_tot)
    rho = 0.9
    s = n + 2 * sum((n - d) * rho**d for d in range(1, n))
    hf = sweep.y[-1, 0] + sweep.y[-1, 1]
    cg_tot = max(2.0 * abs(np.imag(hf)) / (2 * np.pi * f[-1]), 1e-12)
    yl1 = sweep.y[0, 0] + sweep.y[0, 1]
    yl2 = sweep.y[0, 2] + sweep.y[0, 1]
    return WindingModel(L=np.full(n, l_tot / s), Cs=np.full(n, c_eff * n), Cg=np.full(n + 1, cg_tot / (n + 1)),
                        rho=rho, r_dc=r_dc, f_eddy=5e3, beta=0.025, tan_c=0.01,
                        g1=float(np.real(yl1)), b1=float(np.imag(yl1)), g2=float(np.real(yl2)),
                        b2=float(np.imag(yl2)))


@dataclass
class Fingerprint:
    """A fitted reference model.

    Attributes
    ----------
    model : WindingModel
        The fitted winding.
    n_sections : int
        ``N``.
    cost : float
        Weighted residual sum of squares on the whole sweep.
    n_residuals : int
        Real residuals in ``cost``.
    bic : float
        BIC of the fit.
    rms : float
        ``sqrt(cost / n_residuals)`` (1 = at the noise plus model floor).
    resonances : int
        Resonances counted in the data.
    tried : list of dict
        ``{"n", "cost", "bic"}`` for every ``N`` fitted.
    fit_seconds : float
        Wall time of the fit (0 when loaded from the cache... as stored).
    source, digest : str
        Reference file and its SHA-256.
    cached : bool
        Whether this came from the cache.
    """

    model: WindingModel
    n_sections: int
    cost: float
    n_residuals: int
    bic: float
    rms: float
    resonances: int
    tried: list = field(default_factory=list)
    fit_seconds: float = 0.0
    source: str = ""
    digest: str = ""
    cached: bool = False

    def as_dict(self) -> dict:
        """JSON-ready form (for the cache)."""
        return {"model": self.model.as_dict(), "n_sections": self.n_sections, "cost": self.cost,
                "n_residuals": self.n_residuals, "bic": self.bic, "rms": self.rms, "resonances": self.resonances,
                "tried": self.tried, "fit_seconds": self.fit_seconds, "source": self.source, "digest": self.digest,
                "code_version": CODE_VERSION}

    @classmethod
    def from_dict(cls, d: dict) -> "Fingerprint":
        """Inverse of :meth:`as_dict`."""
        return cls(WindingModel.from_dict(d["model"]), int(d["n_sections"]), float(d["cost"]),
                   int(d["n_residuals"]), float(d["bic"]), float(d["rms"]), int(d["resonances"]),
                   list(d["tried"]), float(d["fit_seconds"]), str(d["source"]), str(d["digest"]), True)


def _log(msg: str, progress: bool) -> None:
    if progress:
        print(f"[sfra] {msg}", file=sys.stderr, flush=True)


def _refine(model: WindingModel, n: int) -> WindingModel:
    """The uniform ``model`` redivided into ``n`` equal sections (a warm start for the ``n``-section fit).

    The end-to-end inductance, the series capacitance of the whole winding
    (``Cs / N``), the interior ground capacitance (``(N - 1) Cg``) and the
    coupling per unit length (``rho ** N``) are kept.
    """
    n0 = model.n
    rho = float(model.rho ** (n0 / n))
    d = np.arange(1, n)
    s = n + 2.0 * float(np.sum((n - d) * rho**d))
    cg = np.full(n + 1, float(np.mean(model.Cg[1:-1])) * (n0 - 1) / max(n - 1, 1) if n0 > 1 else model.Cg[0])
    cg[0], cg[-1] = model.Cg[0], model.Cg[-1]
    return model.copy(L=np.full(n, model.total_inductance() / s), Cs=np.full(n, float(np.mean(model.Cs)) * n / n0),
                      Cg=cg, rho=rho, loops=[], coupling_scale=None)


def _fit_n(sweep: Sweep, n: int, max_nfev: int = 60, warm: WindingModel | None = None) -> tuple[WindingModel, float]:
    """Best of the :data:`STARTS` fits (and of ``warm`` redivided) of an ``n``-section winding: (model, cost)."""
    m0 = _start(sweep, n)
    starts = [m0.copy(Cs=m0.Cs * cs, Cg=m0.Cg * cg) for cs, cg in STARTS]
    if warm is not None:
        starts.append(_refine(warm, n))
    best = None
    for start in starts:
        model, cost = _fit_from(sweep, start, max_nfev)
        if best is None or cost < best[1]:
            best = (model, cost)
    return best


def _fit_from(sweep: Sweep, start: WindingModel, max_nfev: int) -> tuple[WindingModel, float]:
    n = start.n
    packer = _Packer(n)
    lo, hi = packer.bounds()
    x = np.clip(packer.pack(start), lo + 1e-9, hi - 1e-9)
    sel = np.arange(0, sweep.frequency_hz.size, DECIMATE)
    sigma = weights(sweep)
    f = sweep.frequency_hz

    def res(xf, keep, free):
        xv = x.copy()
        xv[free] = xf
        return log_residuals(model_y(packer.unpack(xv), f[keep]), sweep.y[keep], sigma[keep])

    free = np.arange(x.size)
    for fmax in BANDS_HZ:
        keep = sel[f[sel] <= fmax]
        if keep.size < 8:
            continue
        with np.errstate(all="ignore"):
            sol = least_squares(res, x[free], bounds=(lo[free], hi[free]), x_scale="jac", max_nfev=max_nfev,
                                args=(keep, free))
        x = x.copy()
        x[free] = sol.x
    model = packer.unpack(x)
    full = log_residuals(model_y(model, f), sweep.y, sigma)
    return model, float(np.sum(full**2))


def fit_fingerprint(sweep: Sweep, n_sections: int | None = None, progress: bool = True) -> Fingerprint:
    """Fit the fingerprint model to a reference sweep, choosing ``N`` by BIC.

    Parameters
    ----------
    sweep : Sweep
        The healthy reference.
    n_sections : int, optional
        Force ``N`` (no search).
    progress : bool
        Progress lines on stderr.

    Raises
    ------
    DiagnosisError
        If no fit ends with finite cost.
    """
    t0 = time.perf_counter()
    nres = count_resonances(sweep)
    if n_sections is not None:
        candidates = [int(n_sections)]
    else:
        n0 = int(np.clip(np.ceil(nres / 2) + 1, 3, 10))  # a series and an anti-resonance per section
        candidates = [n for n in range(n0 - 1, n0 + 3) if n >= 2]
    _log(f"reference {Path(sweep.source).name or '(memory)'}: {nres} resonances above the noise; "
         f"fitting N = {', '.join(map(str, candidates))}", progress)
    tried, best, warm = [], None, {}
    n_r = 2 * sweep.y.size
    queue = list(candidates)
    while queue:
        n = queue.pop(0)
        t = time.perf_counter()
        with threadpool_limits(limits=1):  # small matrices: threaded BLAS only contends for the cores
            model, cost = _fit_n(sweep, n, warm=warm.get(n - 1))
        warm[n] = model
        k = N_PARAMS
        b = bic(cost, n_r, k) if np.isfinite(cost) else np.inf
        tried.append({"n": n, "cost": cost, "bic": b, "rms": float(np.sqrt(cost / n_r))})
        _log(f"  N = {n}: rms {np.sqrt(cost / n_r):.3f} (1 = noise + {MODEL_FLOOR:g} floor), BIC {b:.0f}, "
             f"{time.perf_counter() - t:.0f} s", progress)
        if np.isfinite(b) and (best is None or b < best[2]):
            best = (model, cost, b, n)
        if n_sections is None and not queue and n < MAX_SECTIONS and n - best[3] < PATIENCE:
            queue.append(n + 1)  # a count above the best is still within the patience: try one more
    if best is None:
        raise DiagnosisError(f"{sweep.source}: the reference fit failed for every section count")
    model, cost, b, n = best
    return Fingerprint(model, n, cost, n_r, b, float(np.sqrt(cost / n_r)), nres, tried,
                       time.perf_counter() - t0, sweep.source, sweep.digest)


def cache_dir(explicit: str | os.PathLike | None = None) -> Path:
    """Cache directory: ``explicit``, else ``$PRIS_COSIM_CACHE``, else ``~/.cache/pris-cosim``."""
    if explicit:
        return Path(explicit)
    env = os.environ.get("PRIS_COSIM_CACHE")
    if env:
        return Path(env)
    return Path.home() / ".cache" / "pris-cosim"


def load_or_fit(sweep: Sweep, cache: str | os.PathLike | None = None, n_sections: int | None = None,
                progress: bool = True, use_cache: bool = True) -> Fingerprint:
    """The fingerprint of ``sweep``, from the cache when its file was fitted before.

    The key is the reference file's SHA-256, :data:`CODE_VERSION` and ``n_sections``.
    An unreadable cache entry is refitted; a cache that cannot be written is skipped.
    """
    key = f"{sweep.digest[:24] or 'memory'}-{CODE_VERSION}-{n_sections or 'auto'}.json"
    path = cache_dir(cache) / key
    if use_cache and sweep.digest and path.is_file():
        try:
            fp = Fingerprint.from_dict(json.loads(path.read_text()))
            _log(f"reference model from the cache ({path})", progress)
            return fp
        except (ValueError, KeyError, TypeError, OSError):
            pass
    fp = fit_fingerprint(sweep, n_sections, progress)
    if use_cache and sweep.digest:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_text(json.dumps(fp.as_dict()))
            os.replace(tmp, path)
        except OSError:
            _log(f"cache {path.parent} not writable; the reference model is not cached", progress)
    return fp
