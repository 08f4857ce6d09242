"""The model layer: what an error model is, before anything is derived from it.

The declaration (states, noises, parameters, measurements as sympy
expressions), the safe parsing of equation text into sympy (model files are
data: nothing in them runs), the names a model may not use, loading a model file (YAML,
untrusted data) and its check scenario, transforms that make new state sets
from existing models, the NED/ENU map between frames, units, the WGS-84
constants, and models built in code.  It imports only :mod:`modelgen.errors`
and :mod:`modelgen.fileio`; every other layer builds on it.
"""
