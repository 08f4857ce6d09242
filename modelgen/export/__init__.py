"""Exports: a derived model's F, G, H, Q, R for people and for other tools.

``modelgen derive MODEL --format FORMAT`` writes the matrices of a derived
model as readable text, as JSON (entries as sympy strings with the model's
quantities and parameters), as a LaTeX table like a paper's with the model's
symbols, as an Octave/MATLAB function file of the parameters, or as a
serialized CasADi ``Function`` of the parameter vector.  ``readable`` holds
the one deterministic simplification used for every human-facing entry
(factored, ``R_M + h`` kept together); ``formats`` renders the text formats
and ``casadi_file`` the CasADi function.  This layer sits beside the code
generator: it reads derived models and uses the code generator's escapers for
free text; nothing below it imports it.
"""
