"""The thesis's estimation studies, reproduced end to end.

- :mod:`estimation.studies.two_section` -- thesis 4.1.2-4.1.4 (Table 4.5, case studies 1-5);
- :mod:`estimation.studies.three_section.study` -- thesis 4.2.2-4.2.6 (Tables 4.9, 4.10, Figs. 4.19-4.22);
- :mod:`estimation.studies.hv_transformer` -- thesis 5.2 (Case Studies 1, 2a, 2b, 3, Tables 5.2-5.12);
- :mod:`estimation.studies.real_data` -- lumped and ladder fits of real measured data;
- :mod:`estimation.studies.common` -- rows, identifiability, the resumable study driver.

Run them with ``pris-cosim study NAME [--quick]`` (see :mod:`estimation.cli`).
"""

STUDIES = ("two-section", "three-section", "hv-transformer", "real-data")
