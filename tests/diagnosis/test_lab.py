"""The virtual lab's six responses diagnosed against the model without its frequency-dependent effects.

Thesis chapter 5's question (what the lumped model lacks), asked as a user
would: ``pris-cosim lab --model hv-6section-freqdep --quick`` records the
passive 6-section transformer with a skin effect, a core loss and a
magnetising change written in as passive R-L ladders fitted to the thesis's
(2.4)-(2.6) (:mod:`pris_cosim.circuits.freqdep`), through the PRIS chain with its
noise and quantisation; ``pris-cosim diagnose --model hv-6section-passive``
then fits the catalogue's forms (:mod:`estimation.diagnosis.causes.catalogue`),
none of which is a ladder.
"""

import json
import subprocess
import sys

import pytest


def _run(*args: str, cwd) -> dict:
    out = subprocess.run([sys.executable, "-m", "pris_cosim", *args, "--json"], cwd=cwd, capture_output=True,
                         text=True, check=True)
    return json.loads(out.stdout)


@pytest.mark.slow
@pytest.mark.long
def test_virtual_lab_effects_are_all_named_and_leave_the_rest_near_the_noise(tmp_path):
    """All three effects named (no section added), the final cost within 3x the noise floor."""
    _run("lab", "--model", "hv-6section-freqdep", "--quick", "--out", "lab.csv", cwd=tmp_path)
    d = _run("diagnose", "--measured", "lab.csv", "--model", "hv-6section-passive", cwd=tmp_path)
    assert sorted(d["causes"]) == ["core-loss", "magnetising-inductance", "skin-effect"]
    assert d["extended_cost"] + d["extended_penalty"] < 3 * d["noise_floor"]
