"""Generated data with one hidden effect, for testing and benchmarking the diagnosis.

A case draws a baseline network, hides one effect of the catalogue in the
"measured" responses (or none), adds multiplicative complex noise, and keeps
the truth so that a test can check what the diagnosis names.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pris_cosim.frf import ResponseModel
from pris_cosim.models import Model, cascade, get_model

from .catalogue import CoreLoss, MagnetisingInductance, MissingSection, SkinEffect

FREQUENCY_CAUSES = ("none", "skin-effect", "core-loss", "magnetising-inductance", "missing-section")


@dataclass
class SyntheticCase:
    """Measured-like responses with a known hidden effect."""

    cause: str
    strength: float
    seed: int
    frequency_hz: np.ndarray
    measured: dict[str, np.ndarray]
    baseline: Model
    truth: dict[str, float] = field(default_factory=dict)


def _noisy(z: np.ndarray, noise: float, rng: np.random.Generator) -> np.ndarray:
    return z * (1 + noise * (rng.standard_normal(z.size) + 1j * rng.standard_normal(z.size)) / np.sqrt(2))


def _evaluate(model: Model, f: np.ndarray, ext=None, extra=None) -> dict[str, np.ndarray]:
    circuit = ext.prepare(model.circuit) if ext is not None else model.circuit
    values = circuit.resolve(check=False)
    out: dict[str, np.ndarray] = {}
    for cfg in model.configurations.values():
        rm = ResponseModel(circuit, cfg.port, shorts=cfg.shorts, responses=cfg.responses)
        if ext is None:
            out.update(rm.evaluate(f))
        else:
            out.update(rm.evaluate_grid(f, per_frequency=ext.per_frequency(circuit, values, f, extra)))
    return out


def one_port_case(cause: str, seed: int, strength: float | None = None, noise: float = 0.003,
                  points: int = 300) -> SyntheticCase:
    """A cascade winding (2 or 3 sections, random values) with one hidden effect.

    Parameters
    ----------
    cause : str
        One of :data:`FREQUENCY_CAUSES`.
    seed : int
    strength : float in [0, 1], optional
        Effect size within its detectable range (drawn when omitted).
    noise : float
        Relative complex noise (0.003 = 0.3 %).
    points : int
        Log-spaced frequencies over 1 kHz - 10 MHz.
    """
    if cause not in FREQUENCY_CAUSES:
        raise ValueError(f"unknown cause {cause!r} (known: {', '.join(FREQUENCY_CAUSES)})")
    rng = np.random.default_rng(seed)
    strength = float(rng.uniform(0, 1) if strength is None else strength)
    n = int(rng.integers(2, 4))
    jitter = lambda: rng.uniform(0.7, 1.4, n)  # noqa: E731
    params = dict(R=2.0 * jitter(), L=181e-6 * jitter(), C=970e-12 * jitter(), Cg=1.6e-9 * rng.uniform(0.7, 1.4), k=0.6)
    f = np.logspace(3, 7, points)
    truth: dict[str, float] = {"sections": n}
    if cause == "missing-section":
        extra_R, extra_L, extra_C = 2.0 * rng.uniform(0.7, 1.4), 181e-6 * (0.6 + 0.8 * strength), 970e-12 * rng.uniform(0.7, 1.4)
        true_model = cascade(n + 1, R=list(params["R"]) + [extra_R], L=list(params["L"]) + [extra_L],
                             C=list(params["C"]) + [extra_C], Cg=params["Cg"], k=0.6)
        measured = _evaluate(true_model, f)
        truth["sections"] = n + 1
    else:
        true_model = cascade(n, **params)
        ext, extra = None, None
        if cause == "skin-effect":
            ext, extra = SkinEffect(f0=f[0]), {"a": 10 ** (0.5 + 1.5 * strength), "b": 0.5}
        elif cause == "core-loss":
            zmax = float(np.max(np.abs(_evaluate(true_model, f)["Zin"])))
            ext, extra = CoreLoss(), {"a": zmax * 10 ** (0.3 - 1.0 * strength), "b": 1e5}
        elif cause == "magnetising-inductance":
            ext, extra = MagnetisingInductance(f0=f[0]), {"b": 0.03 + 0.07 * strength}
        measured = _evaluate(true_model, f, ext, extra)
        truth.update(extra or {})
    measured = {k: _noisy(v, noise, rng) for k, v in measured.items()}
    baseline = cascade(n, **params)
    return SyntheticCase(cause, strength, seed, f, measured, baseline, truth)


def two_winding_case(cause: str, seed: int, strength: float | None = None, noise: float = 0.003,
                     points: int = 200) -> SyntheticCase:
    """The 4-section two-winding model (Table 5.4) with one hidden effect; six responses, 10 Hz - 100 kHz."""
    if cause not in FREQUENCY_CAUSES:
        raise ValueError(f"unknown cause {cause!r} (known: {', '.join(FREQUENCY_CAUSES)})")
    rng = np.random.default_rng(seed)
    strength = float(rng.uniform(0, 1) if strength is None else strength)
    base = get_model("hv-4section")
    f = np.logspace(1, 5, points)
    truth: dict[str, float] = {}
    if cause == "missing-section":
        values = base.circuit.resolve()
        circuit, _ = MissingSection(model=base).candidates(values)[0]
        true_model = Model("truth", "", circuit, base.configurations, family=("two-winding", 6, None, False))
        measured = _evaluate(true_model, f)
    else:
        ext, extra = None, None
        if cause == "skin-effect":
            ext, extra = SkinEffect(f0=f[0]), {"a": 10 ** (0.5 + 1.0 * strength), "b": 0.5}
        elif cause == "core-loss":
            ext, extra = CoreLoss(), {"a": 73.29e3 * (1 + strength), "b": 300.0 * 10 ** strength}
        elif cause == "magnetising-inductance":
            ext, extra = MagnetisingInductance(f0=f[0]), {"b": 0.02 + 0.05 * strength}
        measured = _evaluate(base, f, ext, extra)
        truth.update(extra or {})
    measured = {k: _noisy(v, noise, rng) for k, v in measured.items()}
    return SyntheticCase(cause, strength, seed, f, measured, base, truth)
