"""Three-section study machinery: bridge-voltage drive, noise, seeds, Fisher information, the CLI options."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from estimation.search.optimisers import Budget
from estimation.studies import cells
from estimation import modal
from estimation.studies.three_section import cases
from estimation.studies.three_section import study as three
from estimation.studies.three_section import frequency as three_frequency


def test_bridge_drive_reproduces_the_target_and_current_injection_does_not():
    """The target comes from pris_cosim.lab.timedomain; the estimate from the batched engine of the study."""
    params = three.make_params()
    u = params.to_unit(three.TARGET)[None]
    v_rms = float(np.sqrt(np.mean(three.time_target()["v_in"] ** 2)))
    bridge = three.build_approach("time", "rmse", params, drive="bridge")
    current = three.build_approach("time", "rmse", params, drive="current")
    assert bridge.cost_batch(u)[0] < 1e-9 * v_rms
    assert current.cost_batch(u)[0] > 1e-3 * v_rms  # the held current's discretisation discrepancy (Fig. 4.14)
    iemd = three.build_approach("iemd", "rmse", params)
    r = iemd.residuals(params.to_unit({**three.TARGET, "Ls": 1.01 * three.TARGET["Ls"]})[None])
    assert math.isclose(float(np.sqrt(np.sum(r ** 2))), float(iemd.cost_batch(
        params.to_unit({**three.TARGET, "Ls": 1.01 * three.TARGET["Ls"]})[None])[0]), rel_tol=1e-9)


@pytest.mark.parametrize("snr", [60.0, 20.0])
def test_noise_has_the_requested_snr(snr):
    t = np.arange(200_000) / 1e6
    w = {"v_in": 3.0 * np.sin(2 * np.pi * 1e3 * t), "i_in": np.cos(2 * np.pi * 7e3 * t), "time_s": t}
    noisy = cells.add_noise(w, snr, seed=5)
    for k in ("v_in", "i_in"):
        measured = 10 * np.log10(np.var(w[k]) / np.var(noisy[k] - w[k]))
        assert abs(measured - snr) < 0.1
    np.testing.assert_array_equal(noisy["time_s"], t)
    np.testing.assert_array_equal(cells.add_noise(w, None, 5)["v_in"], w["v_in"])


def test_aggregate_counts_successes_and_medians():
    def run(seed, errs, cost):
        return {"case": "c", "errors_percent": dict(zip("ab", errs)), "cost": cost, "evaluations": 100 * seed,
                "wall_s": 2.0, "settings": {"seed": seed}, "trace": [[1, cost]]}
    rows = cells.aggregate([run(1, (1.0, -4.0), 0.3), run(2, (8.0, 0.0), 0.1), run(3, (-2.0, 2.0), 0.2)],
                           lambda r: r["case"])
    (r,) = rows
    assert r["success_rate"] == pytest.approx(2 / 3)
    assert r["errors_percent_median"] == {"a": 1.0, "b": 0.0}
    assert r["errors_percent_range"]["a"] == [-2.0, 8.0]
    assert r["errors_percent"] == {"a": 8.0, "b": 0.0}  # the lowest-cost seed
    assert r["evaluations"] == 200 and r["evals_per_s"] == pytest.approx(600 / 6.0)
    assert r["abs_error_percent_max_median"] == 4.0


def test_fisher_information_of_a_logarithmic_residual_is_its_closed_form():
    """r_j = c_j ln(theta_j / theta_j0): J = diag(c), so the relative sd of theta_j is sigma / c_j."""
    params = three.make_params()
    c = np.array([0.01, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0])

    def residuals(U):
        vals = params.values(U)
        return np.stack([c[j] * np.log(np.asarray(vals[k], float) / three.TARGET[k])
                         for j, k in enumerate(three.NAMES)], axis=-1)

    out = cells.fisher_information(residuals, params, three.TARGET, sigma=0.02)
    for j, k in enumerate(three.NAMES):
        assert out["relative_sd_percent"][k] == pytest.approx(100 * 0.02 / c[j], rel=1e-4)
    assert out["poorly_determined"] == ["Rs"]
    assert out["relative_sensitivity"]["k23"] == pytest.approx(1.0)


def test_convergence_trace_is_the_running_best():
    tr = cells.convergence_trace(np.array([5.0, 3.0, 4.0, np.inf, 1.0]), extra=[(9, 2.0), (12, 0.5)], points=10)
    assert tr[-1] == [12.0, 0.5] and [9.0, 1.0] in tr
    assert [p[1] for p in tr] == sorted((p[1] for p in tr), reverse=True)


@pytest.mark.slow
def test_tiny_study_with_seeds_and_noise_writes_rows_and_figures(tmp_path, monkeypatch):
    def tiny(approach, optimiser, quick):
        glob = {"swarm_size": 8, "max_iter": 2} if optimiser == "pso" else {"restarts": 0, "popsize": 8, "max_iter": 2}
        return {"method": f"{cases.GLOBAL_METHODS[optimiser]}+local",
                "options": {"global_options": glob, "local_options": {"max_iter": 1}, "global_share": 0.9},
                "budget": Budget(max_evals=60), "polish_iterations": 1, "polish_time_s": 10.0,
                "modal": {"restarts": 1, "budget": Budget(max_evals=60), "own_local_evals": 20,
                          "options": {"global_options": glob, "local_options": {"max_iter": 1}, "global_share": 0.9}}}

    monkeypatch.setattr(three, "optimiser_settings", tiny)
    out = tmp_path / "s"
    summary = three.run(quick=True, out=str(out), scheduler="serial", progress=False, approaches=["time"],
                        seeds=2, snr_db=[40.0], optimisers=["pso", "cma"], metrics=["rmse"], search=False)
    rows = {r["case"]: r for r in summary["rows"]}
    assert set(rows) == {"time/pso/rmse", "time/cma/rmse", "time/pso/rmse@40dB", "time/cma/rmse@40dB"}
    for r in rows.values():
        assert {"success_rate", "errors_percent_median", "errors_percent_range", "evaluations", "evals_per_s",
                "non_identifiable", "sensitivity", "cost", "wall_s"} <= set(r)
        assert r["seeds"] == [1, 2] and 0 <= r["success_rate"] <= 1
    assert rows["time/pso/rmse@40dB"]["sensitivity"]["at_snr_db"] == 40.0
    assert (out / "convergence_time.png").is_file() and (out / "study.json").is_file()
    json.loads((out / "study.json").read_text())


@pytest.mark.parametrize("args, word", [
    (["study", "three-section", "--snr-db", "40,abc"], "--snr-db"),
    (["study", "two-section", "--seeds", "2"], "three-section"),
])
def test_study_options_reject_bad_input_with_one_line(args, word, tmp_path):
    p = subprocess.run([sys.executable, "-m", "pris_cosim", *args, "--out", str(tmp_path / "x")],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and p.stdout == ""
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and word in lines[0]
    assert not (tmp_path / "x").exists()


def test_matrix_pencil_recovers_damped_sinusoids():
    fs = 11e6
    k = np.arange(700)
    modes = [(107e3, 0.0075, 3.0), (723e3, 4e-4, 0.5), (886e3, 3e-4, 0.4)]
    y = 0.2 * np.exp(-2e4 * k / fs)
    for f, z, a in modes:
        w = 2 * np.pi * f
        y = y + a * np.exp(-z * w * k / fs) * np.cos(w * np.sqrt(1 - z * z) * k / fs + 0.3)
    poles, amp = modal.matrix_pencil(y, 12, fs)
    f_est, z_est = modal.oscillatory(poles, amp, 3)
    for (f, z, _), fe, ze in zip(modes, f_est, z_est):
        assert fe == pytest.approx(f * np.sqrt(1 - z * z), rel=1e-7)
        assert ze == pytest.approx(z, rel=1e-4)
    assert modal.free_segment(np.array([1, 1, 1, -1, -1, -1, -1, -1, 1]), skip=1) == (4, 8)


def test_modal_guide_is_zero_at_the_target_and_not_elsewhere():
    """Modes read off the pris_cosim.lab.timedomain target against the eigenvalues of the estimate's arrangement."""
    params = three.make_params()
    guide = three.modal_guide(params)
    assert guide.f_t.size == 3
    u = params.to_unit(three.TARGET)
    off = params.to_unit({**three.TARGET, "k12": 0.99 * three.TARGET["k12"]})
    c = guide.cost_batch(np.array([u, off]))
    assert c[0] < 1e-12 and c[1] > 1e-6


def test_response_peaks_locate_resonances_between_grid_points():
    """Second-order resonances: |H| peaks at f0 * sqrt(1 - 1 / (2 Q^2)) (closed form), located to < 0.5 Hz
    on a 49 Hz grid (in a sum, the stronger peak's tail shifts the weaker: checked one at a time)."""
    f = np.arange(1e3, 1e6, 49.0)
    for f0, q in [(91_930.0, 40.0), (722_546.0, 1500.0)]:
        h = 1.0 / (1.0 - (f / f0) ** 2 + 1j * f / (q * f0))
        got = modal.response_peaks(f, h, prominence=0.3)
        assert got.size == 1
        assert abs(got[0] - f0 * math.sqrt(1.0 - 1.0 / (2.0 * q * q))) < 0.5


def test_target_resonances_match_the_analytic_impedance_peaks():
    """Peaks of the simulated target's Welch Zin against peaks of the analytic Zin on a fine grid."""
    from pris_cosim.models.builtin import get_model

    got = three_frequency.frequency_peaks()
    f = np.linspace(3e3, 1e6, 400_000)
    z = get_model(three.NAME).response_set().evaluate(f, {})["Zin"]
    ref = modal.response_peaks(f, z, prominence=0.3)
    assert got.size == ref.size == 3
    # Hann-windowed Welch on a 2.5 MHz record: within 1e-3 (the 200 compared bins are 3 % apart)
    assert np.all(np.abs(got / ref - 1.0) < 1e-3)
