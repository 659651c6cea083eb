"""The staged recipe's rules on a model kind with a closed-form answer (a linear least-squares problem)."""

from __future__ import annotations

import numpy as np

from estimation.parameters import Parameter, ParameterSet
from estimation.recipe import End, Start, run_recipe


class LinearKind:
    """Residuals ``A x - b`` in the unit cube; the answer is ``numpy.linalg.lstsq``'s.

    ``good`` lists the restarts whose descent reaches the minimum; the others stop at a fixed wrong point.
    ``starts`` is how many starts the kind has (then ``start`` gives None).
    """

    def __init__(self, good: set[int], starts: int = 10):
        rng = np.random.default_rng(3)
        self.A = rng.normal(size=(40, 2))
        self.truth = np.array([0.3, 0.7])
        self.b = self.A @ self.truth
        self.params = ParameterSet([Parameter("p", 0.5, 0.0, 1.0, scale="linear"),
                                    Parameter("q", 0.5, 0.0, 1.0, scale="linear")])
        self.verdict_options: dict = {}
        self.good, self.n_starts = good, starts
        self.started: list[int] = []

    def start(self, k: int) -> Start | None:
        if k >= self.n_starts:
            return None
        self.started.append(k)
        return Start(np.array([0.5, 0.5]), 1.0, {"design": 3}, f"start {k}", {"seed": k})

    def descend(self, starts):
        out = []
        for k, s in starts:
            x = self.truth.copy() if k in self.good else np.array([0.9, 0.1])
            out.append(End(x, float(np.sum((self.A @ x - self.b) ** 2)), {**s.runs, "least squares": 5}, "done"))
        return out

    def residuals(self, U: np.ndarray) -> np.ndarray:
        return np.atleast_2d(U) @ self.A.T - self.b

    def data(self) -> np.ndarray:
        return self.b

    def polish(self, x):
        return None


def _kind(good: set[int], starts: int = 10) -> LinearKind:
    return LinearKind(good, starts)


def test_two_restarts_at_the_noise_floor_end_the_recipe():
    kind = _kind(good={0, 1, 2})
    out = run_recipe(kind, restarts=3, max_restarts=8, noise=0.0, progress=False)
    assert kind.started == [0, 1, 2]
    assert np.allclose(out.x, np.linalg.lstsq(kind.A, kind.b, rcond=None)[0])
    assert out.nfev == 3 * (3 + 5 + 1)
    assert [r["runs_per_stage"] for r in out.stages] == [{"design": 3, "least squares": 5}] * 3


def test_more_restarts_while_fewer_than_two_reach_the_floor():
    kind = _kind(good={0, 5})
    out = run_recipe(kind, restarts=3, max_restarts=8, noise=0.0, progress=False)
    assert kind.started == [0, 1, 2, 3, 4, 5]  # the sixth is the second to reach the minimum
    assert out.cost < 1e-20 and out.verdict["restarts"]["count"] == 6


def test_a_kind_out_of_starts_ends_the_restarts():
    kind = _kind(good={0}, starts=2)
    out = run_recipe(kind, restarts=3, max_restarts=8, noise=0.0, progress=False)
    assert kind.started == [0, 1] and len(out.stages) == 2
