"""Analysis of any derived model: covariance recursions and observability.

* :mod:`modelgen.analysis.covariance`: the recursions of a covariance
  analysis on a time-invariant discrete system (open loop, optimal filter,
  the true error covariance of a suboptimal filter's gain sequence);
* :mod:`modelgen.analysis.observability`: the rank of a model's
  observability matrix over a scenario and the directions it cannot see
  (``modelgen observability``).

The core paper's own covariance analysis (its six systems, Table 2, the
sensitivity study and Figs 2-7) is built on these in :mod:`modelgen.table2`.
"""
