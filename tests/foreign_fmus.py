"""FMUs built by another tool (pythonfmu) for the estimation tests, and their records (fmpy).

Nothing here uses pris-cosim: each model is a small linear network written
for pythonfmu, stepped exactly with the matrix exponential of the augmented
matrix while its input is held over each communication step (a DAC-driven
source), and its record is made by stepping it with fmpy's FMI 2.0 / 3.0 slave classes under a held PRBS
(the output at ``t_k`` read after the input ``u[k]`` is set, ``u[k]`` held until ``t_k+1``).
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


#: Current in (A), two voltages out: four coupled sections in series from the driven node 1 to ground, each an
#: R-L branch beside a series capacitance, a ground capacitance at every node; only adjacent sections couple
#: (k12, k23, k34), so couplings near 1 make the inductance matrix indefinite and the FMU refuses them.
FOUR_SECTION_PHYSICS = """
NAMES = ("R1", "R2", "R3", "R4", "L1", "L2", "L3", "L4", "Cs1", "Cs2", "Cs3", "Cs4", "Cg1", "Cg2", "Cg3", "Cg4",
         "k12", "k23", "k34")
START = dict(R1=2.0, R2=2.0, R3=2.0, R4=2.0, L1=1e-3, L2=1e-3, L3=1e-3, L4=1e-3, Cs1=1e-10, Cs2=1e-10,
             Cs3=1e-10, Cs4=1e-10, Cg1=2e-10, Cg2=2e-10, Cg3=2e-10, Cg4=2e-10, k12=0.3, k23=0.3, k34=0.3)


def discretise(p, h):
    # state x = [v1, v2, v3, v4, i1, i2, i3, i4]; branch j runs from node j to node j + 1 (node 5 is ground)
    L = np.array([p["L1"], p["L2"], p["L3"], p["L4"]])
    k = [p["k12"], p["k23"], p["k34"]]
    Lm = np.diag(L)
    for j in range(3):
        Lm[j, j + 1] = Lm[j + 1, j] = k[j] * np.sqrt(L[j] * L[j + 1])
    if np.min(np.linalg.eigvalsh(Lm)) <= 0.0:
        return None, "inductance matrix not positive definite at k12=%.3g, k23=%.3g, k34=%.3g" % tuple(k)
    Cs = [p["Cs1"], p["Cs2"], p["Cs3"], p["Cs4"]]
    Cm = np.diag([p["Cg1"], p["Cg2"], p["Cg3"], p["Cg4"]])
    for j in range(4):
        Cm[j, j] += Cs[j]
        if j < 3:
            Cm[j + 1, j + 1] += Cs[j]
            Cm[j, j + 1] -= Cs[j]
            Cm[j + 1, j] -= Cs[j]
    Ki = np.zeros((4, 4))
    Vl = np.zeros((4, 4))
    for j in range(4):
        Ki[j, j] = -1.0
        Vl[j, j] = 1.0
        if j < 3:
            Ki[j + 1, j] = 1.0
            Vl[j, j + 1] = -1.0
    Ci, Li = np.linalg.inv(Cm), np.linalg.inv(Lm)
    A = np.zeros((8, 8))
    A[:4, 4:] = Ci @ Ki
    A[4:, :4] = Li @ Vl
    A[4:, 4:] = -Li @ np.diag([p["R1"], p["R2"], p["R3"], p["R4"]])
    B = np.concatenate([Ci[:, 0], np.zeros(4)])
    E = expm(np.block([[A, B[:, None]], [np.zeros((1, 9))]]) * h)
    return (E[:8, :8], E[:8, 8]), ""
"""

FOUR_SECTION_FMI2 = """
import numpy as np
from scipy.linalg import expm
from pythonfmu import Fmi2Causality, Fmi2Variability, Fmi2Slave, Real
from pythonfmu.enums import Fmi2Status
""" + FOUR_SECTION_PHYSICS + """

class FourSection(Fmi2Slave):
    author = "test"
    description = "four coupled sections, current in, two voltages out (FMI 2.0)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for n, v in START.items():
            setattr(self, n, v)
            self.register_variable(Real(n, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.i_drive, self.v_1, self.v_4 = 0.0, 0.0, 0.0
        self.x = np.zeros(8)
        self._key = None
        self.register_variable(Real("i_drive", causality=Fmi2Causality.input))
        self.register_variable(Real("v_1", causality=Fmi2Causality.output))
        self.register_variable(Real("v_4", causality=Fmi2Causality.output))

    def exit_initialization_mode(self):
        self.x = np.zeros(8)
        self.v_1, self.v_4 = 0.0, 0.0

    def do_step(self, current_time, step_size):
        key = tuple(getattr(self, n) for n in NAMES) + (step_size,)
        if key != self._key:
            steps, why = discretise(dict(zip(NAMES, key)), step_size)
            if steps is None:  # refused: an error status, no exception
                self.log(why, Fmi2Status.error)
                return False
            (self._Ad, self._Bd), self._key = steps, key
        self.x = self._Ad @ self.x + self._Bd * self.i_drive
        self.v_1, self.v_4 = float(self.x[0]), float(self.x[3])
        return True
"""

FOUR_SECTION_FMI3 = """
import numpy as np
from scipy.linalg import expm
from pythonfmu3 import Fmi3Causality, Fmi3Variability, Fmi3Slave, Float64
from pythonfmu3.enums import Fmi3Status
""" + FOUR_SECTION_PHYSICS + """

class FourSection3(Fmi3Slave):
    author = "test"
    description = "four coupled sections, current in, two voltages out (FMI 3.0)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.time = 0.0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous))
        for n, v in START.items():
            setattr(self, n, v)
            self.register_variable(Float64(n, causality=Fmi3Causality.parameter,
                                           variability=Fmi3Variability.tunable))
        self.i_drive, self.v_1, self.v_4 = 0.0, 0.0, 0.0
        self.x = np.zeros(8)
        self._key = None
        self.register_variable(Float64("i_drive", causality=Fmi3Causality.input))
        self.register_variable(Float64("v_1", causality=Fmi3Causality.output))
        self.register_variable(Float64("v_4", causality=Fmi3Causality.output))

    def exit_initialization_mode(self):
        self.x = np.zeros(8)
        self.v_1, self.v_4 = 0.0, 0.0

    def do_step(self, current_time, step_size):
        key = tuple(getattr(self, n) for n in NAMES) + (step_size,)
        if key != self._key:
            steps, why = discretise(dict(zip(NAMES, key)), step_size)
            if steps is None:  # refused: an error status, no exception
                self.log(why, Fmi3Status.error)
                return False
            (self._Ad, self._Bd), self._key = steps, key
        self.x = self._Ad @ self.x + self._Bd * self.i_drive
        self.v_1, self.v_4 = float(self.x[0]), float(self.x[3])
        self.time = current_time + step_size
        return True
"""

FOUR_TRUTH = {"R1": 3.0, "R2": 2.5, "R3": 2.0, "R4": 3.5, "L1": 1.5e-3, "L2": 1.1e-3, "L3": 0.9e-3, "L4": 1.3e-3,
              "Cs": 0.12e-9, "Cg": 0.35e-9, "k12": 0.42, "k23": 0.36, "k34": 0.48}
#: The FMU's parameters from the estimated ones: every series and ground capacitance shared.
FOUR_TIES = {**{f"Cs{j}": "Cs" for j in range(1, 5)}, **{f"Cg{j}": "Cg" for j in range(1, 5)}}


def fmu_truth(name: str) -> dict[str, float]:
    """The true values of the FMU ``name``'s own parameters (shared values spread through its ties)."""
    m = MODELS[name]
    return _fmu_values(m["truth"], m["ties"]) if "ties" in m else dict(m["truth"])


def _fmu_values(truth, ties):
    out = {k: v for k, v in truth.items() if k not in ("Cs", "Cg")}
    out.update({k: truth[e] for k, e in ties.items()})
    return out


MODELS = {
    "coupled_pair": {"source": CURRENT_IN, "cls": "CoupledPair", "input": "i_drive", "outputs": ["v_top", "v_mid"],
                     "truth": {"R1": 4.0, "R2": 6.0, "L1": 1.2e-3, "L2": 2.0e-3, "k": 0.45, "C1": 0.8e-9,
                               "C2": 1.5e-9, "Cg": 0.6e-9}, "amplitude": 0.01},
    "pi_network": {"source": VOLTAGE_IN, "cls": "PiNetwork", "input": "u_src", "outputs": ["i_src"],
                   "truth": {"Rs": 50.0, "Ca": 2.2e-9, "L": 0.8e-3, "RL": 3.0, "Cb": 1.0e-9, "Rload": 2e3},
                   "amplitude": 5.0},
    "four_section": {"source": FOUR_SECTION_FMI2, "cls": "FourSection", "input": "i_drive", "outputs": ["v_1", "v_4"],
                     "truth": FOUR_TRUTH, "ties": FOUR_TIES, "amplitude": 0.01},
    "four_section_fmi3": {"source": FOUR_SECTION_FMI3, "cls": "FourSection3", "input": "i_drive",
                          "outputs": ["v_1", "v_4"], "truth": FOUR_TRUTH, "ties": FOUR_TIES, "amplitude": 0.01,
                          "builder": "pythonfmu3"},
}

_RECORD = '''
import json, os, sys
import numpy as np
import fmpy
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
fmu, spec, out = sys.argv[1], json.loads(sys.argv[2]), sys.argv[3]
fs, n, hold = spec["fs"], spec["n"], spec["hold"]
reg, bits = [1] * 9, []
while len(bits) * hold < n:                  # maximal-length LFSR, taps 9 and 5
    bits.append(reg[-1])
    reg = [reg[8] ^ reg[4]] + reg[:-1]
u = spec["amplitude"] * np.repeat(2 * np.array(bits) - 1, hold)[:n].astype(float)
t = np.arange(n) / fs
unzipped = fmpy.extract(fmu)
md = fmpy.read_model_description(unzipped)
vr = {v.name: v.valueReference for v in md.modelVariables}
par = [vr[k] for k in spec["truth"]]
val = [float(v) for v in spec["truth"].values()]
three = md.fmiVersion == "3.0"
cls = FMU3Slave if three else FMU2Slave
inst = cls(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier)
inst.instantiate()                           # never freed: the process ends with os._exit
setr, getr = (inst.setFloat64, inst.getFloat64) if three else (inst.setReal, inst.getReal)
if three:
    inst.enterInitializationMode(startTime=0.0)
else:
    inst.setupExperiment(startTime=0.0)
    inst.enterInitializationMode()
setr(par, val)
setr([vr[spec["input"]]], [u[0]])
inst.exitInitializationMode()
outs = [vr[o] for o in spec["outputs"]]
y = np.empty((n, len(outs)))
for k in range(n):                           # output at t_k after the input u[k]; u[k] held until t_k+1
    setr([vr[spec["input"]]], [u[k]])
    y[k] = getr(outs)
    if k < n - 1:
        inst.doStep(currentCommunicationPoint=t[k], communicationStepSize=1 / fs)
cols = [y[:, j] for j in range(len(outs))]
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
    code = (f"import sys; from {m.get('builder', 'pythonfmu')}.builder import FmuBuilder; "
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
    truth = _fmu_values(m["truth"], m["ties"]) if "ties" in m else m["truth"]
    spec = {"fs": fs, "n": n, "hold": hold, "amplitude": m["amplitude"], "input": m["input"],
            "outputs": m["outputs"], "truth": truth, "noise": noise, "seed": seed}
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
