"""Netlist reading and writing: the reference files load and everything round-trips exactly."""

import pytest

from pris_cosim.errors import NetlistError
from pris_cosim.circuits.netlist import format_netlist, parse_netlist, read_netlist, write_netlist

REFERENCE = ["two_section_table4_2.cir", "three_section_table4_7.cir", "hv_transformer_4section_table5_4.cir",
             "hv_transformer_6section_table5_12.cir"]
COUNTS = {"two_section_table4_2.cir": 7, "three_section_table4_7.cir": 15,
          "hv_transformer_4section_table5_4.cir": 36, "hv_transformer_6section_table5_12.cir": 55}


@pytest.mark.parametrize("name", REFERENCE)
def test_reference_netlists_load_and_round_trip(netlist_dir, tmp_path, name):
    c = read_netlist(netlist_dir / name)
    assert len(c.elements) == COUNTS[name]
    c.check_topology()
    path = write_netlist(c, tmp_path / name)
    back = read_netlist(path)
    assert back == c
    assert back.resolve() == c.resolve()  # bit-identical values
    assert format_netlist(back) == format_netlist(c)


def test_values_and_params_from_reference(netlist_dir):
    c = read_netlist(netlist_dir / "three_section_table4_7.cir")
    v = c.resolve()
    assert v["cg1"] == pytest.approx(0.8e-9)
    assert v["cg2"] == pytest.approx(1.6e-9)
    assert v["l3"] == pytest.approx(181e-6)
    assert v["k13"] == pytest.approx(0.8729)
    hv = read_netlist(netlist_dir / "hv_transformer_4section_table5_4.cir")
    assert hv.resolve()["ra1"] == pytest.approx(0.1173)
    assert hv.element("LB4").nodes == ("y4", "0")


def test_syntax_features():
    text = """Title line is a comment
* comment
.param a=2 b={2*a}
.param c = { a * b }  ; trailing comment
R1 in mid {b}
+
L1 mid 0 1m ; inductor
C1 in 0 10nF
V1 src 0 DC 5 AC 1
R2 src in 1k
.control
this is not parsed
.endc
.ac dec 10 1 1k
.end
"""
    c = parse_netlist("* " + text)
    v = c.resolve()
    assert v["r1"] == 4.0 and v["l1"] == 1e-3 and v["c1"] == 10e-9
    assert c.parameter("C").value.evaluate({"a": 2.0, "b": 4.0}) == 8.0
    assert c.element("v1").source_spec == "DC 5 AC 1"
    assert parse_netlist(format_netlist(c)) == c


def test_continuation_line():
    c = parse_netlist("* t\nR1 a 0\n+ 10k\nC1 a 0 1n\n")
    assert c.resolve()["r1"] == 10e3


@pytest.mark.parametrize(
    "text, match",
    [
        ("* t\nR1 a 0 1x2\n", r"<netlist>:2:8: .*'R1'"),
        ("* t\nR1 a 0\n", r":2:1: element 'R1' needs two nodes and a value"),
        ("* t\nQ1 a b c model\n", r":2:1: element type 'Q'"),
        ("* t\n.param a=\n", r":2:9: cannot parse .param"),
        ("* t\nR1 a 0 1\nR1 b 0 2\n", r":3:1: element 'R1' is defined twice"),
        ("* t\n.subckt foo a b\n", r":2:1: .subckt is not supported"),
        ("* t\n*@ port zz\nR1 a 0 1\n", r"port 'zz' is not a node"),
    ],
)
def test_errors_name_file_and_line(text, match):
    with pytest.raises(NetlistError, match=match):
        parse_netlist(text)


def test_missing_file(tmp_path):
    with pytest.raises(NetlistError, match="cannot read netlist"):
        read_netlist(tmp_path / "missing.cir")


def test_write_is_atomic(tmp_path, netlist_dir, monkeypatch):
    target = tmp_path / "out.cir"
    target.write_text("old content\n")
    c = read_netlist(netlist_dir / "two_section_table4_2.cir")
    import pris_cosim.circuits.netlist as nl

    def fail(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(nl.os, "replace", fail)
    with pytest.raises(OSError, match="disk full"):
        write_netlist(c, target)
    assert target.read_text() == "old content\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.cir"]
