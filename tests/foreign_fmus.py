"""FMUs built by another tool (pythonfmu) for the estimation tests, and their records (fmpy).

Nothing here uses pris-cosim: each model is a small linear network written
for pythonfmu, stepped exactly with the matrix exponential of the augmented
matrix while its input is held over each communication step (a DAC-driven
source), and its record is made by fmpy's ``simulate_fmu`` with a held PRBS.
Building and recording run in a subprocess: a pythonfmu FMU may crash the
process that frees it, so the recorder writes its file and exits without
freeing the instance, and a recording killed by a signal is made again.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

#: Current in (A), voltage out: two coupled sections, each an R-L branch beside a capacitance, in series
#: from the driven node to ground; ground capacitance at the driven node.
CURRENT_IN = '''
import numpy as np
from scipy.linalg import expm
from pythonfmu import Fmi2Causality, Fmi2Variability, Fmi2Slave, Real

NAMES = ("R1", "R2", "L1", "L2", "k", "C1", "C2", "Cg")


class CoupledPair(Fmi2Slave):
    author = "test"
    description = "two coupled R-L || C sections, current in, voltage out"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.R1, self.R2, self.L1, self.L2, self.k = 1.0, 1.0, 1e-3, 1e-3, 0.3
        self.C1, self.C2, self.Cg = 1e-9, 1e-9, 1e-9
        self.i_drive = 0.0
        self.v_top = 0.0
        self.v_mid = 0.0
        self.x = np.zeros(4)
        self._key = None
        for n in NAMES:
            self.register_variable(Real(n, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("i_drive", causality=Fmi2Causality.input))
        self.register_variable(Real("v_top", causality=Fmi2Causality.output))
        self.register_variable(Real("v_mid", causality=Fmi2Causality.output))

    def _discretise(self, h):
        key = tuple(getattr(self, n) for n in NAMES) + (h,)
        if key == self._key:
            return
        R1, R2, L1, L2, k, C1, C2, Cg = key[:8]
        M = k * np.sqrt(L1 * L2)
        Li = np.linalg.inv(np.array([[L1, M], [M, L2]]))
        Cm = np.array([[C1 + Cg, -C1], [-C1, C1 + C2]])
        Ci = np.linalg.inv(Cm)
        # x = [v_top, v_mid, i1, i2]; branch 1 from top to mid, branch 2 from mid to ground
        A = np.zeros((4, 4))
        A[:2, 2:] = Ci @ np.array([[-1.0, 0.0], [1.0, -1.0]])
        A[2:, :2] = Li @ np.array([[1.0, -1.0], [0.0, 1.0]])
        A[2:, 2:] = -Li @ np.diag([R1, R2])
        B = np.concatenate([Ci @ np.array([1.0, 0.0]), np.zeros(2)])
        E = expm(np.block([[A, B[:, None]], [np.zeros((1, 5))]]) * h)
        self._Ad, self._Bd, self._key = E[:4, :4], E[:4, 4], key

    def exit_initialization_mode(self):
        self.v_top, self.v_mid = float(self.x[0]), float(self.x[1])

    def do_step(self, current_time, step_size):
        self._discretise(step_size)
        self.x = self._Ad @ self.x + self._Bd * self.i_drive
        self.v_top, self.v_mid = float(self.x[0]), float(self.x[1])
        return True
'''

#: Voltage in (V) behind a known source resistance, current out: a pi network (C, series R-L, C) loaded by
#: a resistance.
VOLTAGE_IN = '''
import numpy as np
from scipy.linalg import expm
from pythonfmu import Fmi2Causality, Fmi2Variability, Fmi2Slave, Real

NAMES = ("Rs", "Ca", "L", "RL", "Cb", "Rload")


class PiNetwork(Fmi2Slave):
    author = "test"
    description = "pi network behind a source resistance, voltage in, current out"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.Rs, self.Ca, self.L, self.RL, self.Cb, self.Rload = 50.0, 1e-9, 1e-3, 1.0, 1e-9, 1e3
        self.u_src = 0.0
        self.i_src = 0.0
        self.x = np.zeros(3)
        self._key = None
        for n in NAMES:
            self.register_variable(Real(n, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("u_src", causality=Fmi2Causality.input))
        self.register_variable(Real("i_src", causality=Fmi2Causality.output))

    def _discretise(self, h):
        key = tuple(getattr(self, n) for n in NAMES) + (h,)
        if key == self._key:
            return
        Rs, Ca, L, RL, Cb, Rload = key[:6]
        # x = [va, vb, iL]
        A = np.array([[-1 / (Rs * Ca), 0.0, -1 / Ca],
                      [0.0, -1 / (Rload * Cb), 1 / Cb],
                      [1 / L, -1 / L, -RL / L]])
        B = np.array([1 / (Rs * Ca), 0.0, 0.0])
        E = expm(np.block([[A, B[:, None]], [np.zeros((1, 4))]]) * h)
        self._Ad, self._Bd, self._key = E[:3, :3], E[:3, 3], key

    def exit_initialization_mode(self):
        self.i_src = float((self.u_src - self.x[0]) / self.Rs)

    def do_step(self, current_time, step_size):
        self._discretise(step_size)
        self.x = self._Ad @ self.x + self._Bd * self.u_src
        self.i_src = float((self.u_src - self.x[0]) / self.Rs)
        return True
'''

MODELS = {
    "coupled_pair": {"source": CURRENT_IN, "cls": "CoupledPair", "input": "i_drive", "outputs": ["v_top", "v_mid"],
                     "truth": {"R1": 4.0, "R2": 6.0, "L1": 1.2e-3, "L2": 2.0e-3, "k": 0.45, "C1": 0.8e-9,
                               "C2": 1.5e-9, "Cg": 0.6e-9}, "amplitude": 0.01},
    "pi_network": {"source": VOLTAGE_IN, "cls": "PiNetwork", "input": "u_src", "outputs": ["i_src"],
                   "truth": {"Rs": 50.0, "Ca": 2.2e-9, "L": 0.8e-3, "RL": 3.0, "Cb": 1.0e-9, "Rload": 2e3},
                   "amplitude": 5.0},
}

_RECORD = '''
import json, os, sys
import numpy as np
import fmpy
fmu, spec, out = sys.argv[1], json.loads(sys.argv[2]), sys.argv[3]
fs, n, hold = spec["fs"], spec["n"], spec["hold"]
reg, bits = [1] * 9, []
while len(bits) * hold < n:                  # maximal-length LFSR, taps 9 and 5
    bits.append(reg[-1])
    reg = [reg[8] ^ reg[4]] + reg[:-1]
u = spec["amplitude"] * np.repeat(2 * np.array(bits) - 1, hold)[:n].astype(float)
t = np.arange(n) / fs
sig = np.zeros(n, dtype=[("time", float), (spec["input"], float)])
sig["time"], sig[spec["input"]] = t, u
unzipped = fmpy.extract(fmu)
md = fmpy.read_model_description(unzipped)
inst = fmpy.instantiate_fmu(unzipped, md, "CoSimulation")      # never freed: the process ends with os._exit
r = fmpy.simulate_fmu(unzipped, stop_time=t[-1], step_size=1 / fs, output_interval=1 / fs, input=sig,
                      output=spec["outputs"], start_values=spec["truth"], model_description=md, fmu_instance=inst)
cols = [np.asarray(r[o], float)[:n] for o in spec["outputs"]]
rng = np.random.default_rng(spec["seed"])
if spec["noise"]:
    cols = [c + spec["noise"] * np.sqrt(np.mean(c ** 2)) * rng.standard_normal(n) for c in cols]
np.savetxt(out, np.column_stack([t, u] + cols), delimiter=",", header=",".join(["time_s", spec["input"]] + spec["outputs"]),
           comments="", fmt="%.15e")
sys.stdout.flush()
os._exit(0)
'''


def build(name: str, dest: Path) -> Path:
    """Build the FMU ``name`` of :data:`MODELS` with pythonfmu into ``dest`` (a subprocess)."""
    m = MODELS[name]
    dest.mkdir(parents=True, exist_ok=True)
    script = dest / f"{m['cls']}.py"
    script.write_text(textwrap.dedent(m["source"]))
    code = ("import sys; from pythonfmu.builder import FmuBuilder; "
            "print(FmuBuilder.build_FMU(sys.argv[1], dest=sys.argv[2]))")
    subprocess.run([sys.executable, "-c", code, str(script), str(dest)], check=True, capture_output=True, text=True)
    fmu = dest / f"{m['cls']}.fmu"
    assert fmu.is_file(), fmu
    return fmu


def record(name: str, fmu: Path, out: Path, fs: float = 2e6, n: int = 2048, hold: int = 4, noise: float = 0.0,
           seed: int = 7) -> Path:
    """A record of the FMU at its truth made by fmpy (subprocess): held PRBS input, outputs, optional noise
    (``noise`` times each output's RMS, Gaussian)."""
    m = MODELS[name]
    spec = {"fs": fs, "n": n, "hold": hold, "amplitude": m["amplitude"], "input": m["input"],
            "outputs": m["outputs"], "truth": m["truth"], "noise": noise, "seed": seed}
    for attempt in range(3):              # a crash inside the foreign FMU's embedded interpreter is retried
        run = subprocess.run([sys.executable, "-c", _RECORD, str(fmu), json.dumps(spec), str(out)],
                             capture_output=True, text=True)
        if run.returncode == 0:
            return out
        if run.returncode > 0:
            break
    raise RuntimeError(f"recording {fmu} failed (exit {run.returncode}): {run.stderr[-1500:]}")


def read(path: Path) -> dict[str, np.ndarray]:
    """Columns of a record written by :func:`record`."""
    names = path.read_text().splitlines()[0].split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    return {k: data[:, j] for j, k in enumerate(names)}
