"""The fingerprint model: an N-section winding fitted to the healthy sweep.

The reference sweep's ``Y11``, ``Y21`` and ``Y22`` are fitted jointly by the
winding of :mod:`estimation.sfra.winding`, with complex log residuals
``ln(Y_model / Y_measured)`` (real part: log-magnitude, imaginary part: phase
in rad) divided by the noise estimated from the data itself
(:func:`estimation.sfra.sweep.estimate_noise`) combined with a model-error
floor.  Above about 100 kHz ``S21`` nears the analyser's noise floor; the
estimated noise grows there and the weights fall with it, without any fixed
band limit.

The section count ``N`` comes from the data: the resonances of the
end-to-end response are counted (peaks of ``|Y21|`` and of ``|1/Y21|``
where the data stand above their noise); a section adds about one series
and one anti-resonance, so ``N0 = ceil(count / 2) + 1``; ``N0 - 1`` to
``N0 + 2`` are fitted (each from :data:`STARTS` starting points, as the
ladder fit has local minima), then ``N + 1`` as long as the largest count
tried has the lowest BIC (up to :data:`MAX_SECTIONS`); the lowest BIC wins.

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

from .sweep import MODEL_FLOOR, Sweep
from .winding import WindingModel, admittance

__all__ = ["Fingerprint", "fit_fingerprint", "load_or_fit", "count_resonances", "model_y", "cache_dir",
           "CODE_VERSION"]

#: Part of the cache key: bump when the model or the fit changes.
CODE_VERSION = "sfra-fingerprint-3"

#: Largest section count the automatic search goes to.
MAX_SECTIONS = 10

#: Continuation bands of the reference fit, Hz.
BANDS_HZ = (2e3, 2e4, 1e5, np.inf)

#: Relative noise above which the end-to-end response is not used to count resonances.
CLEAN_NOISE = 0.03

#: Weight of the uniformity prior on the section parameters (see ``_Packer.prior``).
PRIOR_WEIGHT = 3.0

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
    """Map a winding model to/from a vector of (mostly log) parameters with bounds."""

    def __init__(self, n: int):
        self.n = n

    def pack(self, m: WindingModel) -> np.ndarray:
        return np.concatenate([np.log(m.L), np.log(m.Cs), np.log(m.Cg),
                               [np.log(1.0 - m.rho), np.log(m.r_dc), m.beta, np.log(m.tan_c),
                                np.log(m.f_eddy), m.g1 * 1e5, m.b1 * 1e5, m.g2 * 1e5, m.b2 * 1e5]])

    def unpack(self, x: np.ndarray) -> WindingModel:
        n = self.n
        i = 3 * n + 1
        return WindingModel(L=np.exp(x[:n]), Cs=np.exp(x[n:2 * n]), Cg=np.exp(x[2 * n:i]),
                            rho=float(1.0 - np.exp(x[i])), r_dc=float(np.exp(x[i + 1])),
                            f_eddy=float(np.exp(x[i + 4])), beta=float(x[i + 2]), tan_c=float(np.exp(x[i + 3])),
                            g1=float(x[i + 5] * 1e-5), b1=float(x[i + 6] * 1e-5),
                            g2=float(x[i + 7] * 1e-5), b2=float(x[i + 8] * 1e-5))

    def prior(self, x: np.ndarray) -> np.ndarray:
        """Weak uniformity prior: per-section ``ln L``, ``ln Cs``, ``ln Cg`` about their means.

        Residuals ``PRIOR_WEIGHT * (ln p_i - mean ln p)``: a section ``e`` times
        off the mean costs as much as ``PRIOR_WEIGHT**2`` noise-level residuals
        among thousands, which keeps an ill-conditioned ladder from sending
        single sections to their bounds without hiding what the data need.
        """
        n = self.n
        out = []
        for a, b in ((0, n), (n, 2 * n), (2 * n, 3 * n + 1)):
            v = x[a:b]
            out.append(PRIOR_WEIGHT * (v - v.mean()))
        return np.concatenate(out)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        n = self.n
        lo = np.concatenate([np.full(n, np.log(1e-3)), np.full(n, np.log(1e-13)), np.full(n + 1, np.log(1e-14)),
                             [np.log(1e-5), np.log(1.0), 0.0, np.log(1e-5), np.log(10.0), -100, -100, -100, -100]])
        hi = np.concatenate([np.full(n, np.log(1e2)), np.full(n, np.log(1e-7)), np.full(n + 1, np.log(1e-7)),
                             [np.log(0.7), np.log(1e4), 0.3, np.log(0.5), np.log(1e7), 100, 100, 100, 100]])
        return lo, hi


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


def _fit_n(sweep: Sweep, n: int, max_nfev: int = 60) -> tuple[WindingModel, float]:
    """Best of the :data:`STARTS` fits of an ``n``-section winding: (model, weighted cost)."""
    best = None
    for cs, cg in STARTS:
        m0 = _start(sweep, n)
        model, cost = _fit_from(sweep, m0.copy(Cs=m0.Cs * cs, Cg=m0.Cg * cg), max_nfev)
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
        r = log_residuals(model_y(packer.unpack(xv), f[keep]), sweep.y[keep], sigma[keep])
        return np.concatenate([r, packer.prior(xv)])

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
    tried, best = [], None
    n_r = 2 * sweep.y.size
    queue = list(candidates)
    while queue:
        n = queue.pop(0)
        t = time.perf_counter()
        with threadpool_limits(limits=1):  # small matrices: threaded BLAS only contends for the cores
            model, cost = _fit_n(sweep, n)
        k = 3 * n + 1 + 9
        b = bic(cost, n_r, k) if np.isfinite(cost) else np.inf
        tried.append({"n": n, "cost": cost, "bic": b, "rms": float(np.sqrt(cost / n_r))})
        _log(f"  N = {n}: rms {np.sqrt(cost / n_r):.3f} (1 = noise + {MODEL_FLOOR:g} floor), BIC {b:.0f}, "
             f"{time.perf_counter() - t:.0f} s", progress)
        if np.isfinite(b) and (best is None or b < best[2]):
            best = (model, cost, b, n)
            if n_sections is None and not queue and n < MAX_SECTIONS:
                queue.append(n + 1)  # the largest count tried is still the best: try one more
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
