"""Trade studies: many covariance analyses (and selected Monte Carlo runs) over an error budget's parameters.

A study file (``modelgen/data/studies/*.yaml``) names the paper's truth model,
its analysis scenario and error budget, the parameters to vary (each with its
unit, the budget entries it sets and a list or range of values), the filters
to compare (the paper's optimal and suboptimal filters, or variants of them)
and optionally the cases to fly as Monte Carlo.  :mod:`.studyfile` reads and
checks it completely before any work is submitted; :mod:`.trade` runs every
case as a dask task (:mod:`modelgen.cluster`); :mod:`.outputs` writes the
table (CSV, Parquet), the figures and the summary.
"""
