"""FMUs, Modelica, SSP archives and co-simulation, run in independent importers."""
