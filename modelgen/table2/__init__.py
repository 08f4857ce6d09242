"""The core paper's covariance analysis: its Table 2 and Figs 2-7, reproduced (Yuan Xin & Yu Zaixin, sections 3-6).

Data flow: scenario and error budget (YAML in ``modelgen/data``) -> the
18-state model and the reduced models made from it by ``modelgen.model.transform``
-> derived, discretized matrices -> the covariance recursions of
:mod:`modelgen.analysis.covariance` (pure inertial, optimal filter, true
covariance of suboptimal filters) -> Table 2 analogue, sensitivity table and
Figs 2-7 analogues.

* :mod:`~modelgen.table2.scenario` and :mod:`~modelgen.table2.budget`: the
  paper's flight and its Table 1 error budget;
* :mod:`~modelgen.table2.suboptimal` and :mod:`~modelgen.table2.systems`: the
  paper's filters as designs, and its six systems;
* :mod:`~modelgen.table2.metrics`: errors in the paper's units, CEP;
* :mod:`~modelgen.table2.inference`: the one value the OCR lost, inferred;
* :mod:`~modelgen.table2.comparison`: our Table 2 beside the paper's;
* :mod:`~modelgen.table2.sensitivity`, :mod:`~modelgen.table2.figures`,
  :mod:`~modelgen.table2.report`: the sensitivity study, Figs 2-7 and
  ``table2.md`` (entry point: :func:`modelgen.table2.report.run_covariance_analysis`).

Trade studies (:mod:`modelgen.study`) run these recursions over grids of
error budgets and filters.
"""
