
import numpy as np
from scipy.linalg import expm
from pythonfmu import Fmi2Causality, Fmi2Variability, Fmi2Slave, Real
from pythonfmu.enums import Fmi2Status

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
