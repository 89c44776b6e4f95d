"""``docs/results.md`` with its tables and plots, generated from the saved runs only.

Everything in the page is computed from ``<out>/<profile>/<experiment>/*.json`` and
``timing.json``, so the numbers always belong to an actual run and the page can be regenerated
(``--report-only``) without running anything. Summary CSVs go next to the results; PNG plots go to
``docs/figures/exp*_*.png``.

Its parts, by what they do: ``page`` (the page in order), ``peg_block`` (the peg's sections,
which are also written alone: ``qg_experiments.peg_report``), ``grid_sections``, ``peg_sections``,
``comparison`` and ``aggregate_section`` (the sections' text), ``markdown`` (numbers, tables and
cells as text), ``plots`` (the figures), ``tables`` (CSV and JSON beside the page),
``divergence`` (which critics diverged).
"""
from qg_experiments.report.grid_sections import THESIS
from qg_experiments.report.page import write_report

__all__ = ["write_report", "THESIS"]
