"""Covariance analysis of the core paper (seed 000, sections 3-6).

Data flow: scenario and error budget (YAML in ``modelgen/data``) -> the
18-state model and the reduced models made from it by ``modelgen.model.transform``
-> derived, discretized matrices -> covariance recursions (pure inertial,
optimal filter, true covariance of suboptimal filters) -> Table 2 analogue,
sensitivity table and Figs 2-7 analogues.

Entry point: :func:`modelgen.analysis.covariance_report.run_covariance_analysis`.
The observability of a model over a scenario (``modelgen observability``)
is :mod:`modelgen.analysis.observability`.
"""
