"""The derive layer: the matrices a Kalman filter needs, from a declared model.

F, G, H, Q, R by symbolic differentiation (sympy), the same Jacobians
through CasADi as a cross-check, discretization (Taylor series as in the
paper, Van Loan as the exact reference) and the dense numpy Kalman filter
that is the numerical reference for generated code and the simulations.  It
builds on :mod:`modelgen.model` and is used by code generation, the checks,
analysis, simulation and the navigator.
"""
