"""Run estim8 on an input-driven FMU and a recorded waveform, as its documentation shows a user to.

This script runs inside a throwaway virtual environment that holds estim8 (``bench_estimate_fmu.py --peers``
creates it and calls this script with that environment's Python); it imports nothing from pris-cosim.

estim8's ``FmuModel.simulate`` calls fmpy's ``simulate_fmu`` without ``input=``, so an FMU with an input
sees its start value (0 V) and no error is raised. :class:`RecordDrivenFmuModel` passes the record's input
column as fmpy's input signal; fmpy applies it at every communication point and the FMU holds it over the
step, as the record was made. It also counts the FMU runs and keeps the best point evaluated, written after
every run to ``--progress``. At the wall-time cap (``--wall``) the objective raises, the optimiser stops, and
the best point evaluated so far is reported (``"stopped": "wall-time cap"``).

The method is estim8's global method for single-core estimation: scipy's differential evolution
(``method="de"``), whose default ``polish=True`` finishes with L-BFGS-B from the best member. The
metric is the weighted sum of squares (``"WSS"``) with each output's error set to a fixed fraction of its
RMS, so that the current (mA) and the voltage (V) weigh alike.

Usage (with the environment's Python)::

    python estim8_driver.py --fmu F.fmu --record record.csv --truth truth.json --input u_drive \
        --outputs i_port,v_port --free L_a,L_b,... --maxiter 20 --out result.json --progress progress.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--fmu", required=True)
    p.add_argument("--record", required=True, help="CSV with time_s, the input and the outputs")
    p.add_argument("--truth", required=True, help="JSON with {'truth': {name: value}}")
    p.add_argument("--input", required=True)
    p.add_argument("--outputs", required=True, help="comma-separated output names")
    p.add_argument("--free", required=True, help="comma-separated parameters to estimate")
    p.add_argument("--lower", type=float, default=0.2, help="lower bound as a fraction of the truth")
    p.add_argument("--upper", type=float, default=5.0, help="upper bound as a multiple of the truth")
    p.add_argument("--maxiter", type=int, default=20, help="differential-evolution generations")
    p.add_argument("--popsize", type=int, default=15, help="scipy's popsize (members = popsize x free values)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--wall", type=float, default=900.0, help="wall-time cap of the estimate, s")
    p.add_argument("--out", required=True)
    p.add_argument("--progress", required=True)
    a = p.parse_args()

    import fmpy
    import estim8
    from estim8.models import FmuModel

    rec = pd.read_csv(a.record)
    t = rec["time_s"].to_numpy()
    fs = (t.size - 1) / (t[-1] - t[0])
    outputs = a.outputs.split(",")
    free = a.free.split(",")
    truth = json.loads(Path(a.truth).read_text())["truth"]
    signal = np.zeros(t.size, dtype=[("time", np.float64), (a.input, np.float64)])
    signal["time"], signal[a.input] = t, rec[a.input].to_numpy()
    state = {"runs": 0, "best": np.inf, "best_x": None, "t0": time.perf_counter()}
    progress = Path(a.progress)

    class RecordDrivenFmuModel(FmuModel):
        """estim8's FMU model with the record's input passed to fmpy (held over each communication step)."""

        def simulate(self, t0, t_end, stepsize, parameters={}, observe=None, replicate_ID=None, r_tol=None,
                     solver="CVode"):
            self._fmu.reset()
            params = self.parameters.copy()
            params.update(parameters)
            observe = observe or self.observables
            raw = fmpy.simulate_fmu(filename=self._unzip_dir, start_time=t0, stop_time=t_end,
                                    output_interval=stepsize, output=observe, start_values=params,
                                    fmi_type=self.fmi_type, input=signal, model_description=self._model_description,
                                    fmu_instance=self._fmu, terminate=False)
            state["runs"] += 1
            sim = {"time": raw["time"], **{o: np.array(raw[o]) for o in observe}}
            return estim8.datatypes.Simulation(sim, replicate_ID=replicate_ID or estim8.datatypes.Constants.SINGLE_ID)

    fixed = {k: v for k, v in truth.items() if k not in free}
    model = RecordDrivenFmuModel(a.fmu, fmi_type="CoSimulation", default_parameters=fixed)
    data = rec.set_index("time_s")[outputs]
    errors = pd.DataFrame({o: np.full(t.size, 0.005 * float(np.sqrt(np.mean(data[o] ** 2)))) for o in outputs},
                          index=data.index)
    bounds = {k: [a.lower * truth[k], min(a.upper * truth[k], 0.99) if k.startswith("k") else a.upper * truth[k]]
              for k in free}
    est = estim8.Estimator(model=model, bounds=bounds, data=estim8.datatypes.Experiment(data, errors=errors),
                           t=[float(t[0]), float(t[-1]), 1.0 / fs], metric="WSS")

    objective = est.objective

    class WallCap(Exception):
        """The wall-time cap was reached."""

    def counted(theta):
        if time.perf_counter() - state["t0"] > a.wall:
            raise WallCap
        f = objective(theta)
        if f < state["best"]:
            state["best"], state["best_x"] = float(f), [float(v) for v in theta]
        doc = {"runs": state["runs"], "wall_s": time.perf_counter() - state["t0"], "best_cost": state["best"],
               "best": dict(zip(free, state["best_x"] or [])), "finished": False}
        tmp = progress.with_suffix(".tmp")
        tmp.write_text(json.dumps(doc))
        tmp.replace(progress)
        return f

    est.objective = counted
    truth_cost = objective(np.array([truth[k] for k in free]))
    state["runs"] = 0
    state["t0"] = time.perf_counter()
    try:
        res, info = est.estimate(method="de", max_iter=a.maxiter, n_jobs=1,
                                 optimizer_kwargs={"seed": a.seed, "popsize": a.popsize, "polish": True})
        res, cost, stopped = {k: float(v) for k, v in res.items()}, float(info.fun), str(info.message)
        if state["best"] < cost:  # the polish may end above the best point it evaluated
            res, cost = dict(zip(free, state["best_x"])), state["best"]
    except WallCap:
        res, cost, stopped = dict(zip(free, state["best_x"])), state["best"], "wall-time cap"
    wall = time.perf_counter() - state["t0"]
    doc = {"peer": f"estim8 {estim8.__version__}", "method": "de (scipy differential evolution, polish L-BFGS-B)",
           "estimate": res,
           "errors_percent": {k: 100 * (float(res[k]) - truth[k]) / truth[k] for k in free},
           "runs": state["runs"], "wall_s": wall, "cost": cost, "truth_cost": float(truth_cost),
           "stopped": stopped, "maxiter": a.maxiter, "popsize": a.popsize, "wall_cap_s": a.wall}
    Path(a.out).write_text(json.dumps(doc, indent=1))
    print(json.dumps(doc), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
