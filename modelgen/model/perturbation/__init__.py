"""Error models derived from the navigation equations, by symbolic perturbation.

Instead of typing the linear error equations, a model states the nonlinear
local-level mechanization (attitude C_b^n, velocity v^n, geodetic position
L, lambda, h), the sensor models, the definition of each error state and the
measurements as functions of the navigation state.  This subpackage derives

    d(x)/dt = F x + G w,   z = H x + v

exactly to first order:

1. *Perturb.*  The true navigation state is written as the computed one
   composed with the error: v_t = v - dv, p_t = p - dp and
   C_t = (I + [phi x]) C (the phi-angle: the computed attitude is
   C = (I - [phi x]) C_t).  The true sensor inputs come from inverting the
   sensor model, e.g. measured rate = (I + diag(s_g)) w + b_g + w_g.
2. *Differentiate.*  The error rates are computed-minus-true rates of the same
   equations, d(dv)/dt = f_v(computed) - f_v(true); for the attitude the exact
   first-order kinematics of the phi-angle, d(phi)/dt = -w_in x phi + dw_in -
   C dw_ib (the one step that needs C C^T = I, done once here).  F, G and H
   are Jacobians at zero error (``sympy.Matrix.jacobian``).
3. *Change variables.*  Declared error states that are linear, position-
   dependent combinations of those primitive errors (position in metres,
   psi-angle, velocity error in the computed frame) follow from
   F = (T F_0 + dT/dt) T^-1, G = T G_0, H = H_0 T^-1, with dT/dt along the
   computed trajectory.
4. *Approximate, by name.*  Each declared approximation is a pure function of
   the derivation (:data:`~.approximations.APPROXIMATIONS`); the terms it removes are kept as
   :class:`~.problem.NeglectedTerm` records (matrix, row, column, the symbolic term),
   so that nothing is dropped silently.
5. *Simplify* with one fixed pipeline (:func:`~.simplification.simplify_entry`), so that the
   result is the same text run to run.

The Earth's radii and gravity are carried as functions of position
(``R_M(L)``, ``R_N(L)``, ``g(L, h)``) while deriving, so that their derivatives
are visible as terms; at the end they become the model's parameters
(``meridian_radius`` ...) and their derivatives the WGS-84 formulas of
:func:`~.simplification.earth_derivative_rules`.

Sources: Shin (2005), "Estimation techniques for low-cost inertial
navigation", ch. 4 (phi-angle NED error model); Groves (2013), "Principles of
GNSS, Inertial, and Multisensor Integrated Navigation Systems", ch. 5 and 14;
Benson (1975), "A comparison of two approaches to pure-inertial and Doppler-
inertial error analysis" (psi-angle); NIMA TR8350.2 (WGS-84 radii and normal
gravity).

The steps live in one module each:

* :mod:`.problem`: what the engine is given (:class:`~.problem.NavigationProblem`: the
  mechanization's symbols, the error definition, the sensor models, the measurement
  functions) and what it returns (:class:`~.problem.ErrorEquations`, :class:`~.problem.NeglectedTerm`);
* :mod:`.linearization`: steps 1 and 2, the primitive error equations F_0, G_0, H_0;
* :mod:`.change_of_variables`: step 3, the declared error states;
* :mod:`.approximations`: step 4, the named approximations;
* :mod:`.simplification`: step 5, Earth functions to parameters and WGS-84 formulas, one simplification;
* :mod:`.derivation`: the checks on a problem and the whole derivation (:func:`~.derivation.derive_error_equations`).
"""
