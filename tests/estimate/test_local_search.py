"""The staged least squares shared by the estimation engines: stages, caps, stops on progress."""

from __future__ import annotations

import numpy as np

from estimation.search.local_search import staged_least_squares


def _problem(target: np.ndarray, floor: float = 0.0):
    """Residuals of a smooth curve fit with two stages (a short and a long abscissa range); the minimum is
    ``target`` (closed form: the curve is evaluated at the target itself), plus a constant floor."""
    t = np.linspace(0.0, 1.0, 200)
    count = {"n": 0}

    def curve(x: np.ndarray, m: int) -> np.ndarray:
        return np.exp(-3 * x[0] * t[:m]) * np.cos(4 * x[1] * t[:m]) + x[2] * t[:m]

    def residual(x: np.ndarray, stage: int) -> tuple[np.ndarray, float]:
        count["n"] += 1
        r = np.concatenate([curve(x, stage) - curve(target, stage), [floor]])
        return r, float(np.sqrt(np.mean(r ** 2)))

    return residual, count


def test_stages_reach_the_minimum_and_report_their_runs():
    target = np.array([0.3, 0.6, 0.45])
    residual, count = _problem(target)
    out = staged_least_squares(residual, np.array([0.5, 0.5, 0.5]), [40, 200], cap=200, counter=lambda: count["n"],
                               label=lambda s: f"first {s}")
    assert np.allclose(out["x"], target, atol=1e-7)
    assert [s["stage"] for s in out["per_stage"]] == ["first 40", "first 200"]
    assert sum(s["runs"] for s in out["per_stage"]) == count["n"]
    assert out["cost"] < 1e-9


def test_a_stage_stops_at_its_cap_and_on_progress():
    target = np.array([0.3, 0.6, 0.45])
    residual, count = _problem(target, floor=1.0)  # a floor the cost cannot fall below: progress stalls
    out = staged_least_squares(residual, np.array([0.9, 0.1, 0.9]), [200, 200], cap=12, counter=lambda: count["n"],
                               finish=False)
    assert all(s["runs"] <= 12 for s in out["per_stage"])
    assert "cap of 12" in out["message"] or "progress" in out["message"]
    residual, count = _problem(target, floor=1.0)
    out = staged_least_squares(residual, np.array([0.31, 0.61, 0.45]), [200, 200], cap=10_000,
                               counter=lambda: count["n"], finish=False)
    assert "stopped on progress" in out["message"] or "termination" in out["message"]
    assert count["n"] < 10_000
