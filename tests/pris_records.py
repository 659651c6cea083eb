"""PRIS records of the thesis's three-section winding made by ngspice, written here without the package.

The deck is written from scratch: a PWL bridge voltage from a PRBS of this
module's own LFSR, optionally the bridge's parasitic ``Lsw`` / ``Csw`` and a
contact resistance, the source's series R, L, C (thesis 4.2.2: 150 Ohm,
4 mH, 1 uF), the three-section winding of thesis Table 4.7 and optionally a
capacitance across its port. ngspice's transient (from rest, maximum step a
tenth of the sampling interval) is interpolated to the sample instants; the
bridge voltage column holds the commanded level from each sample to the next.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

#: Feedback taps of maximal-length LFSRs (x^n + x^m + 1).
TAPS = {5: (5, 3), 6: (6, 5), 7: (7, 6), 8: (8, 6, 5, 4)}

WINDING = """* three-section winding, thesis Table 4.7
R1 n1 x1 0.083
L1 x1 n2 181u
Cs1 n1 n2 0.97n
R2 n2 x2 0.083
L2 x2 n3 181u
Cs2 n2 n3 0.97n
R3 n3 x3 0.083
L3 x3 0 181u
Cs3 n3 0 0.97n
Cg1 n1 0 0.8n
Cg2 n2 0 1.6n
Cg3 n3 0 1.6n
K12 L1 L2 0.8792
K13 L1 L3 0.8729
K23 L2 L3 0.8564
"""

#: Section 2 of Table 4.7 as two sections (half its resistance each, twice its series capacitance each, 1.6 nF
#: from the new node to ground): L2 + L2b + 2 k sqrt(L2 L2b) = 181 uH with k = 0.9, the couplings of the two to
#: L1 and L3 chosen so that the merged section's mutual inductances are Table 4.7's.
FOUR_SECTIONS = """* four sections: section 2 of Table 4.7 made two
R1 n1 x1 0.083
L1 x1 n2 181u
Cs1 n1 n2 0.97n
R2 n2 x2 0.0415
L2 x2 m2 47.63u
Cs2 n2 m2 1.94n
R2b m2 y2 0.0415
L2b y2 n3 47.63u
Cs2b m2 n3 1.94n
R3 n3 x3 0.083
L3 x3 0 181u
Cs3 n3 0 0.97n
Cg1 n1 0 0.8n
Cg2 n2 0 1.6n
Cgm m2 0 1.6n
Cg3 n3 0 1.6n
K12 L1 L2 0.8568
K12b L1 L2b 0.8568
K13 L1 L3 0.8729
K22b L2 L2b 0.9
K23 L2 L3 0.8347
K2b3 L2b L3 0.8347
"""


def prbs(order: int) -> np.ndarray:
    """One period (``2^order - 1`` bits) of a maximal-length sequence, as +-1."""
    reg = [1] * order
    out = []
    for _ in range(2 ** order - 1):
        out.append(reg[-1])
        fb = 0
        for t in TAPS[order]:
            fb ^= reg[t - 1]
        reg = [fb] + reg[:-1]
    return np.where(np.array(out) == 1, 1.0, -1.0)


def record(order: int = 6, fclk: float = 100e3, fs: float = 10e6, periods: int = 2, vdc: float = 100.0,
           rpris: float = 150.0, lpris: float = 4e-3, cpris: float = 1e-6, contact: float = 0.0,
           lsw: float = 0.0, csw: float = 0.0, stray: float = 0.0, noise: float = 0.0, seed: int = 1,
           winding: str = WINDING) -> dict[str, np.ndarray]:
    """``time_s, v_bprbs, v_in, i_in`` of the arrangement; ``noise``: relative standard deviation (of each
    channel's own standard deviation) of white noise added to ``v_in`` and ``i_in``; ``winding``: the
    winding's SPICE lines (its port ``n1``, default the three sections of Table 4.7)."""
    exe = shutil.which("ngspice")
    if exe is None:
        raise FileNotFoundError("ngspice")
    bits = np.tile(prbs(order), periods) * vdc
    per_bit = int(round(fs / fclk))
    K = bits.size * per_bit
    t = np.arange(K) / fs
    pts = [f"0 {float(bits[0])!r}"]
    for j in np.flatnonzero(np.diff(bits)) + 1:
        tj = j / fclk
        pts += [f"{float(tj - 5e-13)!r} {float(bits[j - 1])!r}", f"{float(tj + 5e-13)!r} {float(bits[j])!r}"]
    pwl = "\n+ ".join(" ".join(pts[i:i + 4]) for i in range(0, len(pts), 4))
    lines = ["* PRIS arrangement for the replay tests", f"Vb b 0 PWL({pwl})"]
    node = "b"
    if lsw > 0:
        lines += [f"Lsw b h {lsw!r}", f"Csw h 0 {csw!r}"]
        node = "h"
    if contact > 0:
        lines.append(f"Rcontact {node} hc {contact!r}")
        node = "hc"
    lines += [f"Rp {node} r1 {rpris!r}", "Vsense r1 r1s 0", f"Lp r1s r2 {lpris!r}", f"Cp r2 n1 {cpris!r}"]
    if stray > 0:
        lines.append(f"Cstray n1 0 {stray!r}")
    deck = "\n".join(lines) + "\n" + winding + (
        f".tran {1 / fs!r} {float(t[-1])!r} 0 {0.1 / fs!r} uic\n.control\nset wr_singlescale\noption numdgt=16\nrun\n"
        "wrdata out.txt v(n1) i(Vsense)\n.endc\n.end\n")
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "deck.cir").write_text(deck)
        proc = subprocess.run([exe, "-b", "deck.cir"], cwd=tmp, capture_output=True, text=True, timeout=600, check=False)
        if not (Path(tmp) / "out.txt").exists():
            raise RuntimeError("ngspice: " + (proc.stdout + proc.stderr)[-2000:])
        data = np.loadtxt(Path(tmp) / "out.txt", ndmin=2)
    tn, vn, inn = data[:, 0], data[:, 1], data[:, 2]
    v = np.interp(t, tn, vn)
    i = np.interp(t, tn, inn)
    if noise > 0:
        rng = np.random.default_rng(seed)
        v = v + noise * np.std(v) * rng.standard_normal(K)
        i = i + noise * np.std(i) * rng.standard_normal(K)
    return {"time_s": t, "v_bprbs": np.repeat(bits, per_bit), "v_in": v, "i_in": i}


def write_csv(rec: dict[str, np.ndarray], path: Path) -> Path:
    np.savetxt(path, np.column_stack([rec["time_s"], rec["v_bprbs"], rec["v_in"], rec["i_in"]]), delimiter=",",
               header="time_s,v_bprbs,v_in,i_in", comments="", fmt="%.12g")
    return path
