"""estimate with a user's netlist in the loop, checked against the built-in model of the same circuit."""

import json
import subprocess
import sys

from estimation.cli import run_estimate



def _cfg(netlist_dir, **kw):
    cfg = {"netlist": str(netlist_dir / "two_section_table4_2.cir"), "port": "in", "approach": "frequency", "seed": 1,
           "parameters": {"L1": {"min": 1, "max": 100}, "C2": {"min": 1e-10, "max": 1e-8}},
           "target": {"kind": "simulated", "values": {"L1": 12, "C2": 1.3e-9}}}
    cfg.update(kw)
    return cfg


def test_netlist_frequency_recovers_values(netlist_dir):
    out = run_estimate(_cfg(netlist_dir), progress=False)
    assert out["model"] == "two_section_table4_2"
    assert all(abs(e) < 2.0 for e in out["errors_percent"].values())


def test_netlist_matches_builtin_model(netlist_dir):
    """The netlist file and the built-in two-section model hold the same circuit: same estimate."""
    a = run_estimate(_cfg(netlist_dir), progress=False)
    cfg = _cfg(netlist_dir)
    del cfg["netlist"], cfg["port"]
    cfg["model"] = "two-section"
    b = run_estimate(cfg, progress=False)
    for k in a["estimate"]:
        assert abs(a["estimate"][k] / b["estimate"][k] - 1) < 1e-6


def test_unknown_port_one_line(tmp_path, netlist_dir):
    p = tmp_path / "c.json"
    p.write_text(json.dumps(_cfg(netlist_dir, port="nowhere")))
    r = subprocess.run([sys.executable, "-m", "pris_cosim.cli", "estimate", "--config", str(p)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "nowhere" in r.stderr
