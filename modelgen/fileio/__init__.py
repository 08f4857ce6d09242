"""Files in and out: the one place that finds shipped data and writes results.

``datafiles`` finds files shipped with the package (models, data) and reads
YAML with errors that name the file and line; ``output`` writes files and
whole folders atomically (staged, then renamed) so that an interrupted run
never leaves a half-written result.  It sits just above :mod:`modelgen.errors`
and below every other layer.
"""
