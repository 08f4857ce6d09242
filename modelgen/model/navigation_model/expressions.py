"""Written equations and expression measurements: the names an expression of the navigation state may use.

:func:`state_namespace` lists them (C_b_n, v_n, latitude ..., the mechanization's
own for ecef, the body-axis inputs); :func:`read_written_equations` reads the
velocity or position rate a file writes itself (``navigation.equations``) and
:func:`expression_measurement` a measurement ``of: expression``.
"""

from __future__ import annotations

from typing import Any, Callable, Mapping

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.file_fields import scalar_text
from modelgen.model.mechanizations.local_level import MeridianRadius, PrimeVerticalRadius, gravity_vector
from modelgen.model.navigation_model.section import (
    ERROR_QUANTITIES,
    WRITABLE_EQUATIONS,
    MeasurementParts,
    SectionReader,
)
from modelgen.model.perturbation.problem import Mechanization, NavigationState
from modelgen.model.vectors import parse_vector_expression, tree_size


def state_namespace(state: NavigationState, mech: Mechanization, frame: str, parameters: Mapping[str, sp.Symbol]) -> dict[str, Any]:
    """The names a written equation or measurement expression may use (README lists them)."""
    if hasattr(mech, "expression_names"):  # a mechanization with names of its own (ecef: C_b_e, v_e, r_e ...)
        return {**parameters, **mech.expression_names(state), **_body_names(state)}
    L, lam, h = state.position
    return {
        **_body_names(state),
        **parameters,
        "C_b_n": state.attitude,
        "v_n": state.velocity,
        "latitude": L,
        "longitude": lam,
        "height": h,
        "f_n": state.specific_force,
        "omega_ie_n": mech.earth_rate(state),
        "omega_en_n": mech.transport_rate(state),
        "g_n": gravity_vector(frame, state.position),
        "R_M": MeridianRadius(L),
        "R_N": PrimeVerticalRadius(L),
    }


def _body_names(state: NavigationState) -> dict[str, Any]:
    """The sensed inputs in body axes: the body rate w_ib^b (``omega_ib_b``) and the specific force f^b (``f_b``).

    The true state's body rate is the sensed one corrected by the gyro errors, so an
    odometer with a lever arm (``transpose(C_b_n)*v_n + cross(omega_ib_b, l)``) gets
    its gyro-bias columns; ``f_b`` is C^T f^n of the state.
    """
    names: dict[str, Any] = {"f_b": state.attitude.T * state.specific_force}
    if state.body_rate is not None:
        names["omega_ib_b"] = state.body_rate
    return names


def expression_measurement(read: SectionReader, entry: Mapping, key: str, namespace: Callable[[], dict]) -> MeasurementParts:
    """A measurement written as an expression of the navigation state (:func:`state_namespace`)."""
    if "expression" not in entry:
        raise ModelError(f"{read.at(key)}: a measurement 'of: expression' needs 'expression'")
    text = scalar_text(entry["expression"], read.at(f"{key}.expression"), f"{key}.expression")
    where = f"{read.at(f'{key}.expression')}: {key}.expression"

    def function(state: NavigationState, computed: NavigationState, mech: Mechanization) -> sp.Matrix:
        value = parse_vector_expression(text, state_namespace(state, mech, mech.frame, namespace()), where)
        return value if isinstance(value, sp.MatrixBase) else sp.Matrix([value])

    count = len(entry["symbols"]) if isinstance(entry.get("symbols"), list) else 1
    units = entry.get("units", ["1"] * count)
    if not isinstance(units, list) or len(units) != count:
        raise ModelError(f"{read.at(f'{key}.units')}: {key}.units must list {count} units")
    return function, None, [str(u) for u in units], count, None


def read_written_equations(read: SectionReader, section: Mapping, frame: str, namespace: Callable[[], dict]) -> dict[str, Callable]:
    """``equations:``: the velocity or position rate written out (vector expressions of :func:`state_namespace`)."""
    raw = section.get("equations")
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        raise ModelError(f"{read.at('navigation.equations')}: 'navigation.equations' must map a quantity to its rate")
    out = {}
    for quantity, text in raw.items():
        key = f"navigation.equations.{quantity}"
        if quantity not in WRITABLE_EQUATIONS:
            has = "has error states, but its kinematics are fixed (C' = C [w_ib x] - [w_in x] C)" if quantity == "attitude" else "has no error state"
            raise ModelError(
                f"{read.at(key)}: navigation equation for {quantity!r}, which {has}; equations may be written for "
                f"{', '.join(WRITABLE_EQUATIONS)} (error states: {', '.join(ERROR_QUANTITIES)})"
            )
        body = scalar_text(text, read.at(key), key)
        where = f"{read.at(key)}: {key}"

        def equation(state: NavigationState, mech: Mechanization, body: str = body, where: str = where) -> sp.Matrix:
            value = parse_vector_expression(body, state_namespace(state, mech, frame, namespace()), where)
            if not isinstance(value, sp.MatrixBase) or value.shape != (3, 1):
                raise ModelError(f"{where}: the rate must be a 3-vector, got {'a scalar' if not isinstance(value, sp.MatrixBase) else f'{value.rows}x{value.cols}'}")
            _check_derivative_size(value, body, where)
            return value

        out[quantity] = equation
    return out


#: Most nodes a derivative of a written navigation equation's element may have.  The
#: perturbation differentiates, composes and simplifies each element: a product of n
#: factors has derivatives of n terms of n factors, and 40 factors took minutes (hostile-input audit;
#: 15 factors, 2,300 nodes, take 4 s).  The built-in velocity equation's have under 80.
MAX_DERIVATIVE_NODES = 2000


def _check_derivative_size(value: sp.Matrix, body: str, where: str) -> None:
    """Refuse a written equation whose derivative by some symbol has more than :data:`MAX_DERIVATIVE_NODES` nodes."""
    for element in value:
        for symbol in sorted(element.free_symbols, key=str):
            if tree_size(sp.diff(element, symbol), MAX_DERIVATIVE_NODES) > MAX_DERIVATIVE_NODES:
                raise ModelError(
                    f"{where}: {body[:60]!r}{'...' if len(body) > 60 else ''} has a derivative of more than "
                    f"{MAX_DERIVATIVE_NODES} operations, too large to derive the error equations from; write it in a smaller "
                    "form (a product of many factors grows with the square of their number)"
                )
