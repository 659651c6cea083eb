"""Wall and CPU time of the PRIS record replay with and without its missing-section candidate (prints figures).

Two ngspice records of 12,600 samples (``tests/pris_records.py``: PRBS6 at 100 kHz, 10 MS/s, two periods, the
4.2.2 source, 0.2 % noise on ``v_in`` and ``i_in``): the three-section winding of thesis Table 4.7 (nothing
hidden) and ``FOUR_SECTIONS`` (its section 2 made two), both diagnosed against the three-section netlist. Per
record and setting: the causes named, the structure, the wall time and the process's CPU time. Needs ngspice.

Usage::

    python benchmarks/bench_replay_sections.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from pris_records import FOUR_SECTIONS, WINDING, record  # noqa: E402

import estimation.diagnosis.waveform.replay as replay  # noqa: E402
from pris_cosim.circuits.netlist import parse_netlist  # noqa: E402
from pris_cosim.measured.formats import Waveforms  # noqa: E402


def main() -> int:
    records = {"three sections recorded": record(noise=0.002),
               "four sections recorded": record(noise=0.002, winding=FOUR_SECTIONS)}
    structures = replay.section_structures
    for label, search in (("with missing-section", structures), ("without", lambda circuit, port: [])):
        replay.section_structures = search
        for name, rec in records.items():
            w = Waveforms(rec["time_s"], rec["v_bprbs"], rec["v_in"], rec["i_in"])
            t, c = time.perf_counter(), time.process_time()
            d = replay.diagnose_pris_record(w, 150.0, 4e-3, 1e-6, circuit=parse_netlist(WINDING + ".end\n"),
                                            port="n1", progress=False)
            model = next((s.get("model", "") for s in d.steps if s["cause"] == "missing-section"), "")
            print(f"{label:21s} {name:24s} causes {d.causes or ['none']} {model} | wall "
                  f"{time.perf_counter() - t:.1f} s, CPU {time.process_time() - c:.1f} s", flush=True)
    replay.section_structures = structures
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
