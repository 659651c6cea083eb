"""FMUs and systems: C code generation, FMI 2.0/3.0 packaging, Modelica text, SSP archives, co-simulation masters."""
