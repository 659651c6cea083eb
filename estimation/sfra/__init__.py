"""SFRA fault diagnosis: a winding model fitted to a healthy two-port sweep, and the change that explains a new one.

Modules: :mod:`~estimation.sfra.winding` (the N-section model),
:mod:`~estimation.sfra.sweep` (reading sweeps, noise from the data),
:mod:`~estimation.sfra.fingerprint` (reference fit, N by BIC, cache),
:mod:`~estimation.sfra.faults` (catalogue and selection),
:mod:`~estimation.sfra.indices` (CC, ASLE, SD per band),
:mod:`~estimation.sfra.report` (Markdown and figures),
:mod:`~estimation.sfra.cli` (the ``diagnose --reference`` path).
"""
