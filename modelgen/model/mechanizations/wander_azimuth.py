"""The wander-azimuth mechanization: a local-level frame w turned about the vertical by the wander angle alpha.

Groves (2013) section 5.3.5; Titterton & Weston (2004) section 3.5.4; Savage
(2000) ch. 4 and 12.  The w-frame is NED turned about the down axis: north is
(cos alpha, sin alpha, 0) in w axes (C_n^w = R_z(-alpha)), so that with the free
wander law

    alpha' = -lambda' sin L

the transport rate has no vertical component, omega_ew^w = (rho_x, rho_y, 0),
and nothing divides by cos L.  The navigation equations are

    C' = C [w_ib x] - [(w_ie + w_ew) x] C,   v' = f^w - (2 w_ie + w_ew) x v + g^w,
    (C_e^w)' = -[w_ew x] C_e^w,             h' = -v_z,

with w_ie^w = W k, k = C_e^w (0, 0, 1) = (cos alpha cos L, sin alpha cos L, -sin L)
the Earth's axis in w axes (the third column of C_e^w), and the horizontal
transport rate written in k (Savage eq. 4.4.1.1-x, Titterton & Weston eq. 3.80):

    rho_H = (1/(R_N + h)) (v_y, -v_x) - D (-k_y, k_x) (k_x v_x + k_y v_y),
    D = e^2/(1 - e^2) R_M / ((R_M + h) (R_N + h))   [= (1/(R_M + h) - 1/(R_N + h)) / cos^2 L],

gravity g^w = (0, 0, g(L, h)) (WGS-84 normal gravity along the down axis, as the
local-level mechanization).  Every term is finite at the poles.

Position is carried as C_e^w and h.  The engine perturbs coordinates, so the
position is given to it as a chart about the operating point C_0:
C_e^w = exp(-[theta x]) C_0 (theta = 0 at the point, theta' = (I + 1/2 [theta x]) w_ew
to first order) and h: four coordinates, one more than the position has (the
wander angle).  The error states are the ones that need no true wander angle
(Benson 1975's psi-angle, Savage's dR^N; Scherzinger & Reid 1994): in the
computed w-frame,

    psi (C_b^w = (I - [psi x]) C_e^w C_b^e true),  dv = v^w - C_e^w v^e_true,  dr = C_e^w (r^e - r^e_true) (metres),

so ``attitude: psi``, ``velocity: computed_frame`` and ``position: metres``.
The frame angle d(theta) = theta_c - theta_t between the computed and the true
w-frames has a vertical component (the wander-angle error combined with the
longitude error) that no declared error depends on: it is carried as a
placeholder state during the derivation and dropped at the end, after checking
that nothing depends on it (:func:`modelgen.model.perturbation.derivation`).
The horizontal frame angle follows from the horizontal position error as the
transport rate from the velocity: d(theta)_H = K dr_H, K = rho_H / v_H above.

The derived F, G, H read the position through k (parameters ``wander_dcm_13``,
``wander_dcm_23``, ``wander_dcm_33``: C_e^w's third column), h and the radii and
gravity at sin L = -k_z: no latitude, longitude or wander angle on its own.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import sympy as sp

from modelgen.model import wgs84
from modelgen.model.mechanizations.local_level import EarthSymbols, _vector, skew

#: Annotations name the engine's NavigationState (modelgen.model.perturbation) as text (no import cycle).
NavigationState = "modelgen.model.perturbation.problem.NavigationState"

FRAME = "WANDER"
AXES = ("x", "y", "z")
#: The error forms the wander frame has: the ones that need no true wander angle (module doc).
ERROR_FORMS = {"attitude": ("psi",), "velocity": ("computed_frame",), "position": ("metres",)}

# Earth quantities as undefined functions of the chart (theta_x, theta_y, h) while deriving.  They depend on the
# chart through s = sin L = -k_z(theta) only: d/d(theta_x) = k_y d/ds, d/d(theta_y) = -k_x d/ds (:func:`derivative_rules`).
#: A = 1/(R_N + h), the transverse curvature: the curvature K is a polynomial in A and D (below).
WanderTransverseCurvature = sp.Function("WanderTransverseCurvature")
#: B = 1/(R_M + h), the meridian curvature (only in the rules: D' in h, and D cos^2 L = B - A).
WanderMeridianCurvature = sp.Function("WanderMeridianCurvature")
WanderGravity = sp.Function("WanderGravity")
#: D = e^2/(1 - e^2) R_M / ((R_M + h)(R_N + h)) = (B - A) / cos^2 L, finite at the poles.
WanderCurvatureDifference = sp.Function("WanderCurvatureDifference")
#: dD/ds and dg/ds (s = sin L), values in :meth:`WanderAzimuth.earth_function_rules`.
WanderCurvatureDifferenceSlope = sp.Function("WanderCurvatureDifferenceSlope")
WanderGravitySlope = sp.Function("WanderGravitySlope")
#: Q = 1/det K: K^-1 = adj(K) Q is a polynomial too, its derivatives Q' = -Q^2 (det K)' (:func:`derivative_rules`),
#: and every product of the change of variables is reduced modulo Q det K = 1 and the ellipsoid's relations
#: (:func:`reduce_by_relations`): polynomial division, no gcd.  det K = A (A + D cos^2 L) = A B.
WanderInverseDeterminant = sp.Function("WanderInverseDeterminant")
EARTH_FUNCTIONS = (
    WanderTransverseCurvature, WanderMeridianCurvature, WanderGravity, WanderCurvatureDifference,
    WanderCurvatureDifferenceSlope, WanderGravitySlope, WanderInverseDeterminant,
)

#: C_e^w's third column k_0 at the operating point (the Earth's axis in w axes): symbols and parameter names.
AXIS_SYMBOLS = ("Cew13", "Cew23", "Cew33")
AXIS_NAMES = ("wander_dcm_13", "wander_dcm_23", "wander_dcm_33")

#: The chart's rotation-vector coordinates (zero at the operating point; never in a result).
CHART = tuple(sp.Symbol(f"wander_chart_theta_{a}", real=True) for a in AXES)


def chart_position(height: sp.Symbol) -> sp.Matrix:
    """The engine's position coordinates of the computed state: (theta_x, theta_y, theta_z, h)."""
    return _vector((*CHART, height))


def earth_axis(axis: sp.Matrix, position: sp.Matrix) -> sp.Matrix:
    """k = C_e^w (0, 0, 1) at chart coordinates theta: (I - [theta x]) k_0 = k_0 + k_0 x theta."""
    theta = _vector(position[:3])
    return axis + axis.cross(theta)


def frame_angle_jacobian(position: sp.Matrix) -> sp.Matrix:
    """J = I - 1/2 [theta x]: d(theta) = J (theta_c - theta_t) at chart coordinates theta_c (first order)."""
    return sp.eye(3) - skew(_vector(position[:3])) / 2


def curvature(axis: sp.Matrix, position: sp.Matrix) -> sp.Matrix:
    """K (2x2): rho_H = K v_H, and d(theta)_H = K dr_H (module doc); polynomial in A = 1/(R_N + h) and D."""
    k = earth_axis(axis, position)
    theta_x, theta_y, _, h = position
    D = WanderCurvatureDifference(theta_x, theta_y, h)
    a = WanderTransverseCurvature(theta_x, theta_y, h)
    return sp.Matrix([[D * k[0] * k[1], a + D * k[1] ** 2], [-a - D * k[0] ** 2, -D * k[0] * k[1]]])


def curvature_determinant(axis: sp.Matrix, position: sp.Matrix) -> sp.Expr:
    """det K = A (A + D (k_x^2 + k_y^2)) as a polynomial (= 1/((R_M + h)(R_N + h)) on the WGS-84 ellipsoid)."""
    K = curvature(axis, position)
    return sp.expand(K[0, 0] * K[1, 1] - K[0, 1] * K[1, 0])


def curvature_inverse(axis: sp.Matrix, position: sp.Matrix) -> sp.Matrix:
    """K^-1 = adj(K) Q, Q = 1/det K the function :data:`WanderInverseDeterminant` (no division: a polynomial)."""
    K = curvature(axis, position)
    theta_x, theta_y, _, h = position
    return sp.Matrix([[K[1, 1], -K[0, 1]], [-K[1, 0], K[0, 0]]]) * WanderInverseDeterminant(theta_x, theta_y, h)


def _functions(position: sp.Matrix) -> tuple[sp.Expr, ...]:
    """A, B, D, dD/ds, g, dg/ds, Q applied to the chart (theta_x, theta_y, h)."""
    arguments = (position[0], position[1], position[3])
    return tuple(f(*arguments) for f in (
        WanderTransverseCurvature, WanderMeridianCurvature, WanderCurvatureDifference, WanderCurvatureDifferenceSlope,
        WanderGravity, WanderGravitySlope, WanderInverseDeterminant))


def derivative_rules(axis: sp.Matrix, position: sp.Matrix) -> dict:
    """The first derivatives of the Earth functions at the chart's origin, exact on the ellipsoid:

    d/d(theta_x) = k_y d/ds, d/d(theta_y) = -k_x d/ds (s = sin L = -k_z); dA/dh = -A^2, dD/dh = -D (A + B)
    (D = c R_M A B); dA/ds = -A^2 dR_N/ds = -s D A^2 Q, since dR_N/ds = (R_N - R_M) s / cos^2 L (the ellipsoid's
    d(R_N cos L)/dL = -R_M sin L) = s D / (A B); dQ/dc = -Q^2 d(det K)/dc.  dD/ds, dg/ds and dg/dh stay symbols.
    """
    theta_x, theta_y, _, h = position
    kx, ky, kz = axis
    A, B, D, D_s, g, g_s, Q = _functions(position)
    A_s = kz * D * A**2 * Q  # -s D A^2 Q, s = -k_z
    rules = {
        sp.Derivative(A, theta_x): ky * A_s, sp.Derivative(A, theta_y): -kx * A_s, sp.Derivative(A, h): -A**2,
        sp.Derivative(D, theta_x): ky * D_s, sp.Derivative(D, theta_y): -kx * D_s, sp.Derivative(D, h): -D * (A + B),
        sp.Derivative(g, theta_x): ky * g_s, sp.Derivative(g, theta_y): -kx * g_s,
    }
    determinant = curvature_determinant(axis, position)
    rules.update({sp.Derivative(Q, c): -Q**2 * determinant.diff(c).xreplace(rules) for c in (theta_x, theta_y, h)})
    return rules


def relations(axis: sp.Matrix, position: sp.Matrix) -> list[sp.Expr]:
    """The polynomials that vanish at the operating point: Q det K - 1, D (k_x^2 + k_y^2) - (B - A), |k|^2 - 1."""
    kx, ky, kz = axis
    A, B, D, _, _, _, Q = _functions(position)
    return [Q * curvature_determinant(axis, position) - 1, D * (kx**2 + ky**2) - B + A, kx**2 + ky**2 + kz**2 - 1]


def reduce_by_relations(expr: sp.Expr, basis: Sequence[sp.Expr], generators: Sequence[sp.Symbol]) -> sp.Expr:
    """``expr``, a polynomial, reduced modulo the ideal of ``basis`` (a Groebner basis in ``generators``, lex).

    The remainder is the ideal's unique normal form: an entry that is zero on the ellipsoid (K^-1 K = I,
    the cancelled curvature terms of dT/dt) reduces to exactly 0, and no gcd is computed.
    """
    expr = sp.expand(expr)
    if expr == 0:
        return expr
    # the other symbols after the basis's generators: a lex Groebner basis stays one (same leading terms)
    variables = [*generators, *sorted(expr.free_symbols - set(generators), key=sp.default_sort_key)]
    try:
        return sp.reduced(expr, list(basis), *variables, order="lex")[1]
    except sp.PolynomialError:  # not a polynomial in the others (a measurement's sqrt): they are coefficients
        pass
    try:
        return sp.reduced(expr, list(basis), *generators, order="lex")[1]
    except sp.PolynomialError:  # not a polynomial in the Earth functions either: exact as it is, only not reduced
        return expr


@dataclass(frozen=True)
class WanderAzimuth:
    """The free wander-azimuth mechanization (module doc); a model may write the velocity rate itself."""

    frame: str
    rotation_rate: sp.Symbol  # the Earth's rotation rate (parameter symbol)
    velocity_equation: Callable[["NavigationState", "WanderAzimuth"], sp.Matrix] | None = None
    position_equation: Callable[["NavigationState", "WanderAzimuth"], sp.Matrix] | None = None

    @property
    def axis(self) -> sp.Matrix:
        """k_0 = C_e^w (0, 0, 1) at the operating point: the parameter symbols :data:`AXIS_SYMBOLS`."""
        return sp.Matrix([sp.Symbol(s, real=True) for s in AXIS_SYMBOLS])

    def earth_rate(self, state: NavigationState) -> sp.Matrix:
        """w_ie^w = W k."""
        return self.rotation_rate * earth_axis(self.axis, state.position)

    def transport_rate(self, state: NavigationState) -> sp.Matrix:
        """w_ew^w = (K v_H, 0): no vertical component (free wander)."""
        rho = curvature(self.axis, state.position) * _vector(state.velocity[:2])
        return _vector((rho[0], rho[1], 0))

    def navigation_rate(self, state: NavigationState) -> sp.Matrix:
        """w_iw^w = w_ie^w + w_ew^w."""
        return self.earth_rate(state) + self.transport_rate(state)

    def gravity(self, state: NavigationState) -> sp.Matrix:
        """g^w = (0, 0, g): normal gravity along the down axis."""
        theta_x, theta_y, _, h = state.position
        return _vector((0, 0, WanderGravity(theta_x, theta_y, h)))

    def velocity_rate(self, state: NavigationState) -> sp.Matrix:
        """v' = f^w - (2 w_ie + w_ew) x v + g^w."""
        if self.velocity_equation is not None:
            return self.velocity_equation(state, self)
        coriolis = (2 * self.earth_rate(state) + self.transport_rate(state)).cross(state.velocity)
        return state.specific_force - coriolis + self.gravity(state)

    def position_rate(self, state: NavigationState) -> sp.Matrix:
        """(theta', h') = ((I + 1/2 [theta x]) w_ew, -v_z): the chart's rates (C_e^w' = -[w_ew x] C_e^w)."""
        theta = _vector(state.position[:3])
        rho = self.transport_rate(state)
        rate = rho + theta.cross(rho) / 2
        return _vector((*rate, -state.velocity[2]))

    def error_frame_angle(self, position: sp.Matrix, position_error: sp.Matrix) -> sp.Matrix:
        """d(theta), the angle of the computed w-frame against the true one, from the chart difference at ``position``.

        exp(-[theta_c x]) exp([theta_t x]) = I - [(I - 1/2 [theta_c x]) (theta_c - theta_t) x] to first order in the
        difference (Baker-Campbell-Hausdorff): the chart's coordinates are the frame angle only at the operating
        point, and dT/dt needs their first-order change along the trajectory.
        """
        return frame_angle_jacobian(position) * _vector(position_error[:3])

    def metres(self, position: sp.Matrix) -> sp.Matrix:
        """(dr_x, dr_y, dr_z, d(theta)_z) from (chart difference, dh): dr_H = K^-1 d(theta)_H, dr_z = -dh (4 x 4)."""
        Ki = curvature_inverse(self.axis, position)
        J = frame_angle_jacobian(position)
        horizontal = Ki * J[:2, :]
        return sp.Matrix([
            [*horizontal.row(0), 0], [*horizontal.row(1), 0], [0, 0, 0, -1], [*J.row(2), 0],
        ])

    def metres_inverse(self, position: sp.Matrix) -> sp.Matrix:
        """(chart difference, dh) from (dr, d(theta)_z): J^-1 (K dr_H, d(theta)_z), dh = -dr_z (4 x 4, first order in theta)."""
        K = curvature(self.axis, position)
        angle = sp.Matrix([[K[0, 0], K[0, 1], 0, 0], [K[1, 0], K[1, 1], 0, 0], [0, 0, 0, 1]])
        theta = _vector(position[:3])
        J_inverse = sp.eye(3) + skew(theta) / 2
        return sp.Matrix.vstack(J_inverse * angle, sp.Matrix([[0, 0, -1, 0]]))

    def to_computed_axes(self, state: NavigationState, computed: NavigationState, vector: sp.Matrix) -> sp.Matrix:
        """A vector in the state's w axes resolved in the computed w axes: C_w^w_c = I - [(theta_c - theta_s) x]."""
        angle = _vector(computed.position[:3]) - _vector(state.position[:3])
        return vector - skew(angle) * vector

    def displacement(self, state: NavigationState, computed: NavigationState) -> sp.Matrix:
        """The state's position in metres along the computed w axes, up to a constant: M (theta, h) at the computed point."""
        return self.metres(computed.position)[:3, :] * state.position

    def earth_function_rules(self, position: sp.Matrix, earth: EarthSymbols) -> dict:
        """The Earth functions at the chart's origin (theta = 0) as parameters and WGS-84 formulas.

        With s = sin L = -k_z and w = 1 - e^2 s^2 (TR8350.2, as the local-level rules with d/dL = cos L d/ds):
        dR_M/ds = 3 e^2 s R_M / w, dR_N/ds = e^2 s R_N / w,
        dg/ds = g s (2 k / (1 + k s^2) + e^2 / w + 8 f h / (a eta)), dg/dh as local level;
        A = 1/(R_N + h), B = 1/(R_M + h), D = c R_M A B (c = e^2/(1 - e^2)) and Q = 1/det K = (R_M + h)(R_N + h)
        (det K = A (A + D cos^2 L) = A B: R_N - R_M = c R_M cos^2 L on the ellipsoid).
        """
        theta_x, theta_y, _, h = position
        e2, a = sp.Float(wgs84.ECCENTRICITY_SQUARED), sp.Float(wgs84.SEMI_MAJOR_AXIS)
        f, m, k = sp.Float(wgs84.FLATTENING), sp.Float(wgs84.GRAVITY_RATIO_M), sp.Float(wgs84.SOMIGLIANA_K)
        s = -self.axis[2]
        w = 1 - e2 * s**2
        eta = 1 - 2 * h * (1 + f + m - 2 * f * s**2) / a + 3 * h**2 / a**2
        g, RM, RN = earth.gravity, earth.meridian_radius, earth.prime_vertical_radius
        ratio = e2 / (1 - e2)
        dRM, dRN = 3 * e2 * s * RM / w, e2 * s * RN / w
        A, B, D, D_s, gravity, g_s, Q = _functions(position)
        rules: dict = {
            A: 1 / (RN + h), B: 1 / (RM + h), D: ratio * RM / ((RM + h) * (RN + h)), Q: (RM + h) * (RN + h), gravity: g,
            D_s: ratio * (dRM / ((RM + h) * (RN + h)) - RM * dRM / ((RM + h) ** 2 * (RN + h)) - RM * dRN / ((RM + h) * (RN + h) ** 2)),
            g_s: g * s * (2 * k / (1 + k * s**2) + e2 / w + 8 * f * h / (a * eta)),
            sp.Derivative(gravity, h): g * (-2 * (1 + f + m - 2 * f * s**2) / a + 6 * h / a**2) / eta,
        }
        rules.update({c: 0 for c in position[:3]})
        return rules

    def declared_products(self, factors: Sequence[sp.Matrix], position: sp.Matrix) -> tuple[sp.Matrix, sp.Matrix, sp.Matrix]:
        """(T F_0 + T') T^-1, T G_0, H_0 T^-1 from the factors (T, T', T^-1, F_0, G_0, H_0), at the chart's origin.

        One pass over each factor: the derivatives of the Earth functions become :func:`derivative_rules`, the
        functions and dg/dh plain symbols, theta 0.  Every product entry is then a polynomial in those and
        Q = 1/det K, reduced modulo :func:`relations` (:func:`reduce_by_relations`), so that K^-1 K = I and the
        curvature terms of T' cancel exactly (one polynomial division per entry; the ``cancel`` of rational
        functions it replaces took minutes); the functions are put back for :meth:`earth_function_rules`.
        """
        functions = _functions(position)
        gravity_gradient = sp.Derivative(functions[4], position[3])
        stand_in = {f: sp.Dummy(f"earth_{k}", real=True) for k, f in enumerate((*functions, gravity_gradient))}
        at_origin = {c: 0 for c in CHART}
        mapping = {k: v.xreplace(stand_in).xreplace(at_origin) for k, v in derivative_rules(self.axis, position).items()}
        mapping.update(stand_in)
        mapping.update(at_origin)
        T, T_dot, T_inv, F0, G0, H0 = (m.xreplace(mapping) for m in factors)
        A, B, D, _, _, _, Q = (stand_in[f] for f in functions)
        kx, ky, kz = self.axis
        generators = [Q, B, A, D, kz, kx, ky]  # lex: B, Q A^2 and k_z^2 are eliminated
        basis = sp.groebner([r.xreplace(mapping) for r in relations(self.axis, position)], *generators, order="lex").exprs
        back = {v: k for k, v in stand_in.items()}
        return tuple(
            m.applyfunc(lambda e: reduce_by_relations(e, basis, generators)).xreplace(back)
            for m in ((T * F0 + T_dot) * T_inv, T * G0, H0 * T_inv)
        )

    def expression_names(self, state: NavigationState) -> dict[str, Any]:
        """The names a written velocity equation may use in the w-frame."""
        return {
            "C_b_w": state.attitude,
            "v_w": state.velocity,
            "height": state.position[3],
            "f_w": state.specific_force,
            "omega_ie_w": self.earth_rate(state),
            "omega_ew_w": self.transport_rate(state),
            "g_w": self.gravity(state),
        }
