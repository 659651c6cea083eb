"""SFRA fault diagnosis: a winding model fitted to a healthy two-port sweep, and the change that explains a new one.

Modules: :mod:`~estimation.diagnosis.sfra.winding` (the N-section model),
:mod:`~estimation.diagnosis.sfra.sweep` (reading sweeps, noise from the data),
:mod:`~estimation.diagnosis.sfra.fingerprint` (reference fit, N by BIC, cache),
:mod:`~estimation.diagnosis.sfra.faults` (catalogue and selection),
:mod:`~estimation.diagnosis.sfra.indices` (CC, ASLE, SD per band),
:mod:`~estimation.diagnosis.sfra.dlt911` (the DL/T 911 factors and verdict),
:mod:`~estimation.diagnosis.sfra.repeatability` (the change against two healthy sweeps),
:mod:`~estimation.diagnosis.sfra.compare` (FRA traces and the standard's comparison),
:mod:`~estimation.diagnosis.sfra.report_fra` (traces with the DL/T 911 bands, the factor table),
:mod:`~estimation.diagnosis.sfra.report` (Markdown and figures),
:mod:`~estimation.diagnosis.sfra.cli` (the ``diagnose --reference`` path).
"""
