"""The PRIS source settings and experiment of each built-in model's own thesis case.

One table: every FMU, Modelica text and command that builds a PRIS
arrangement of a built-in model without explicit source options starts from
the case of that model (thesis 4.1.2, 4.2.2, 5.1.2, 5.1.3):

========================  =====  ======  =======  ==========================  ==========
case                      V_DC   PRBS    f_clk    R, L, C                     sampling
========================  =====  ======  =======  ==========================  ==========
two-section (4.1.2)       30 V   12      10 kHz   31.8 kOhm, 2.53 H, 10 nF    300 kHz, 300 ms
three-section (4.2.2)     100 V  12      100 kHz  150 Ohm, 4 mH, 1 uF         11 MHz, one period
LV terminal (5.1.2)       30 V   16      20 kHz   56 Ohm, 500 uH, 4 uF        1 MHz, one period
HV terminal (5.1.3)       120 V  16      20 kHz   29.7 kOhm, 30 mH, 100 nF,   1 MHz, one period
                                                  snubber 55 Ohm, 10 nF
========================  =====  ======  =======  ==========================  ==========

The two-section case gives no PRBS order; order 12 (4095 bits, 409.5 ms at
10 kHz) covers its 300 ms record. The N-section cascade uses the
three-section element values and therefore its case. The two-winding models
take the LV-terminal case when driven at the LV terminal ``a1`` and the
HV-terminal case when driven at ``b1``.
"""

from __future__ import annotations

from dataclasses import dataclass

from pris_cosim.circuits.arrangement import SourceSettings
from pris_cosim.errors import CircuitError


@dataclass(frozen=True)
class ThesisCase:
    """Source settings and default experiment of one thesis case.

    Attributes
    ----------
    name : str
    section : str
        Thesis section that gives the settings.
    settings : SourceSettings
    fs : float, Hz
        Sampling frequency of the record (the FMU's default step is ``1/fs``
        rounded down to whole nanoseconds that divide the PRBS bit, see
        :attr:`fmu_experiment`).
    duration : float, s
        Record length (the FMU's default stop time).
    """

    name: str
    section: str
    settings: SourceSettings
    fs: float
    duration: float

    @property
    def experiment(self) -> tuple[float, float]:
        """``(stop_time, step_size)`` in s."""
        return self.duration, 1.0 / self.fs

    @property
    def fmu_experiment(self) -> tuple[float, float]:
        """``(stop_time, step_size)`` in s of the FMUs' default experiment.

        The step is the largest one up to ``1/fs`` that is a whole number of
        nanoseconds, divides the PRBS bit and the record (two-section:
        3125 ns for 3333.3 ns; three-section: 80 ns for 90.9 ns), so that
        masters with an integer nanosecond clock keep the PRBS timing.
        """
        from pris_cosim.fmi.codegen import whole_ns_step

        return self.duration, whole_ns_step(1.0 / self.fs, self.settings.fclk, self.duration)


def _period(order: int, fclk: float) -> float:
    return (2**order - 1) / fclk


TWO_SECTION = ThesisCase(
    "two-section", "4.1.2",
    SourceSettings(vdc=30.0, prbs_order=12, fclk=10e3, rpris=31.8e3, lpris=2.53, cpris=10e-9),
    fs=300e3, duration=0.3)
THREE_SECTION = ThesisCase(
    "three-section", "4.2.2",
    SourceSettings(vdc=100.0, prbs_order=12, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6),
    fs=11e6, duration=_period(12, 100e3))
LV_TERMINAL = ThesisCase(
    "LV terminal", "5.1.2",
    SourceSettings(vdc=30.0, prbs_order=16, fclk=20e3, rpris=56.0, lpris=500e-6, cpris=4e-6),
    fs=1e6, duration=_period(16, 20e3))
HV_TERMINAL = ThesisCase(
    "HV terminal", "5.1.3",
    SourceSettings(vdc=120.0, prbs_order=16, fclk=20e3, rpris=29.7e3, lpris=30e-3, cpris=100e-9, rsnub=55.0,
                   csnub=10e-9),
    fs=1e6, duration=_period(16, 20e3))

#: Every case by name.
CASES: dict[str, ThesisCase] = {c.name: c for c in (TWO_SECTION, THREE_SECTION, LV_TERMINAL, HV_TERMINAL)}


def case_for(model: str, port: str | None = None) -> ThesisCase:
    """The thesis case of a built-in model driven at ``port``.

    Parameters
    ----------
    model : str
        Built-in model name (``cascade-N`` and ``cascade-N-open`` for any N).
    port : str, optional
        Driven node; selects the LV (``a1``) or HV (``b1``) terminal case of
        the two-winding models (LV by default).

    Returns
    -------
    ThesisCase

    Raises
    ------
    CircuitError
        The model has no thesis case.
    """
    key = model.strip().lower()
    if key == "two-section":
        return TWO_SECTION
    if key == "three-section" or key.startswith("cascade-"):
        return THREE_SECTION
    if key.startswith("hv-"):
        return HV_TERMINAL if (port or "").lower() == "b1" else LV_TERMINAL
    raise CircuitError(f"model {model!r} has no thesis case")
