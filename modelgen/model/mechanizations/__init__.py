"""Mechanizations: the navigation equations an error model is derived from, behind one protocol.

A mechanization gives the Earth rate, the transport rate, the velocity,
position and attitude rates, gravity, and what the change of variables of the
error states needs (the angle between the true and the computed navigation
frames for a position error, metres per position-error unit).  The engine
(:mod:`modelgen.model.perturbation`) perturbs whatever the protocol returns;
a model file selects one with ``navigation.mechanization`` (default
``local_level``); an unknown name is refused.

Implemented: ``local_level`` (NED or ENU axes, geodetic position;
:mod:`~modelgen.model.mechanizations.local_level`) and ``ecef`` (e-frame
position, velocity and attitude, WGS-84 J2 gravity;
:mod:`~modelgen.model.mechanizations.ecef`) and ``wander_azimuth`` (a local-level frame turned
by the wander angle, free wander: no vertical transport rate, valid through the poles;
:mod:`~modelgen.model.mechanizations.wander_azimuth`).  Adding one: a module
here with a class that satisfies :class:`Mechanization`, registered in
:data:`MECHANIZATIONS` (README, "How to add ... a mechanization").

Two hooks are optional: ``earth_function_rules(position, earth)``, the mechanization's own Earth
functions and their derivatives as parameters and formulas (ecef: |r^e|; wander azimuth: its curvatures),
and ``declared_products(factors, position)``, which forms F, G, H of the declared errors from the
factors of the change of variables itself (wander azimuth: at its chart's origin, reduced modulo the
ellipsoid's relations so that K^-1 K = I cancels without a gcd).
"""

from __future__ import annotations

from typing import Callable, Protocol

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.mechanizations import ecef, local_level, wander_azimuth
from modelgen.model.mechanizations.ecef import Ecef
from modelgen.model.mechanizations.local_level import LocalLevel
from modelgen.model.mechanizations.wander_azimuth import WanderAzimuth

#: The engine's navigation state (modelgen.model.perturbation), named as text: the engine imports this package.
NavigationState = "modelgen.model.perturbation.problem.NavigationState"


class Mechanization(Protocol):
    """What the error-model engine asks of a mechanization (every vector resolved in its navigation frame)."""

    frame: str

    def earth_rate(self, state: "NavigationState") -> sp.Matrix:
        """w_ie, the Earth's rotation rate."""

    def transport_rate(self, state: "NavigationState") -> sp.Matrix:
        """w_en, the navigation frame's rotation with respect to the Earth."""

    def navigation_rate(self, state: "NavigationState") -> sp.Matrix:
        """w_in = w_ie + w_en: the rate the attitude kinematics C' = C [w_ib x] - [w_in x] C subtract."""

    def velocity_rate(self, state: "NavigationState") -> sp.Matrix:
        """v'."""

    def position_rate(self, state: "NavigationState") -> sp.Matrix:
        """The rate of the position coordinates."""

    def gravity(self, state: "NavigationState") -> sp.Matrix:
        """g at the state's position."""

    def error_frame_angle(self, position: sp.Matrix, position_error: sp.Matrix) -> sp.Matrix:
        """d(theta) between the true and the computed navigation frames for a position error (psi-angle, computed-frame velocity)."""

    def metres(self, position: sp.Matrix) -> sp.Matrix:
        """M with (navigation-frame metres) = M (position error): the ``metres`` position-error form."""

    def metres_inverse(self, position: sp.Matrix) -> sp.Matrix:
        """M^-1: the position error from navigation-frame metres."""


#: Mechanizations by the name a model file gives in ``navigation.mechanization``: each makes its
#: mechanization from (frame, Earth-rate symbol, written velocity equation, written position equation).
MECHANIZATIONS: dict[str, Callable[..., Mechanization]] = {"local_level": LocalLevel, "ecef": Ecef, "wander_azimuth": WanderAzimuth}
#: every registered mechanization's Earth functions (R_M(L), g(L, h), ...): the engine stands them in as symbols
#: while differentiating (modelgen.model.perturbation.linearization); a new mechanization's module lists its own
EARTH_FUNCTIONS: tuple[type, ...] = tuple(f for module in (local_level, ecef, wander_azimuth) for f in module.EARTH_FUNCTIONS)
#: The navigation frames (a model file's ``frame``) each mechanization resolves its vectors in.
MECHANIZATION_FRAMES: dict[str, tuple[str, ...]] = {
    "local_level": ("NED", "ENU"), "ecef": ("ECEF",), "wander_azimuth": (wander_azimuth.FRAME,),
}
#: Error forms each mechanization has (None: every form of the engine).
MECHANIZATION_ERROR_FORMS: dict[str, dict[str, tuple[str, ...]] | None] = {
    "local_level": None, "ecef": ecef.ERROR_FORMS, "wander_azimuth": wander_azimuth.ERROR_FORMS,
}
#: Approximations that mean something only in a local-level frame (latitude, radii of curvature, a vertical axis).
LOCAL_LEVEL_APPROXIMATIONS = frozenset({
    "constant_radii", "single_earth_radius", "no_height_in_radii", "gravity_height_only", "free_air_gradient",
    "free_vertical_channel", "level_flight", "no_vertical_channel", "damped_vertical_channel",
    "no_earth_rate_position_terms", "no_transport_rate_position_terms", "constant_gravity",
    "pseudorange_at_computed_position",  # ecef: the position is in metres already (M = I), the displacement exact
})
#: Approximations each mechanization accepts (None: all of the engine's).
MECHANIZATION_APPROXIMATIONS: dict[str, frozenset[str] | None] = {
    "local_level": None, "ecef": frozenset({"no_gravity_gradient"}), "wander_azimuth": frozenset(),
}


def mechanization_named(name: str, where: str = "navigation.mechanization") -> Callable[..., Mechanization]:
    """The mechanization registered as ``name``, or a ModelError listing the known ones."""
    if name not in MECHANIZATIONS:
        raise ModelError(f"{where}: unknown mechanization {name!r} (known: {', '.join(sorted(MECHANIZATIONS))})")
    return MECHANIZATIONS[name]
