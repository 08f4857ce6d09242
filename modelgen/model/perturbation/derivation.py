"""The whole perturbation: a problem checked, then F, G, H derived step by step.

:func:`check_problem` refuses an inconsistent :class:`~modelgen.model.perturbation.problem.NavigationProblem`
before anything is derived; :func:`derive_error_equations` runs the steps
(:mod:`~modelgen.model.perturbation.linearization`, :mod:`~modelgen.model.perturbation.change_of_variables`,
:mod:`~modelgen.model.perturbation.approximations`, :mod:`~modelgen.model.perturbation.simplification`)
and records the entries each declared approximation changed as neglected terms;
under ``no_vertical_channel`` the vertical states are carried as placeholders and
removed at the end.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Sequence

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.perturbation.approximations import APPROXIMATIONS, EQUATION_APPROXIMATIONS, scoped
from modelgen.model.perturbation.change_of_variables import declared_stage
from modelgen.model.perturbation.linearization import primitive_stage
from modelgen.model.perturbation.problem import (
    ATTITUDE_FORMS,
    POSITION_FORMS,
    VELOCITY_FORMS,
    ErrorDefinition,
    ErrorEquations,
    NavigationProblem,
    NeglectedTerm,
    Stage,
    declared_navigation_states,
)
from modelgen.model.perturbation.simplification import finish, readable_term, simplify_entry


def check_problem(problem: NavigationProblem) -> None:
    """Refuse an inconsistent problem before deriving: frame, forms, approximation names, states without equations."""
    from modelgen.model.mechanizations import MECHANIZATION_APPROXIMATIONS, MECHANIZATION_ERROR_FORMS, MECHANIZATION_FRAMES, mechanization_named

    mechanization_named(problem.mechanization_name)
    frames = MECHANIZATION_FRAMES[problem.mechanization_name]
    if problem.frame not in frames:
        raise ModelError(f"navigation frame {problem.frame!r} is not one of {', '.join(frames)} (the {problem.mechanization_name} mechanization's)")
    e = problem.errors
    own_forms = MECHANIZATION_ERROR_FORMS[problem.mechanization_name] or {}
    for what, form, forms in (("attitude", e.attitude, ATTITUDE_FORMS), ("velocity", e.velocity, VELOCITY_FORMS), ("position", e.position, POSITION_FORMS)):
        forms = own_forms.get(what, forms)
        if form not in forms:
            raise ModelError(f"{what} error form {form!r} is not one of {', '.join(forms)} (the {problem.mechanization_name} mechanization's)")
    accepted = MECHANIZATION_APPROXIMATIONS[problem.mechanization_name]
    foreign = [a for a in problem.approximations if a in APPROXIMATIONS and accepted is not None and a not in accepted]
    if foreign:
        raise ModelError(
            f"approximation {foreign[0]!r} does not apply to the {problem.mechanization_name} mechanization "
            f"(it has: {', '.join(sorted(accepted)) or 'none'})"
        )
    if accepted is None and "no_gravity_gradient" in problem.approximations:
        raise ModelError("approximation 'no_gravity_gradient' is the ecef mechanization's (local level: constant_gravity, free_vertical_channel)")
    expected = 2 if "no_vertical_channel" in problem.approximations else 3
    for what, states, count in (("attitude", e.attitude_states, 3), ("velocity", e.velocity_states, expected), ("position", e.position_states, expected)):
        if len(states) != count:
            reason = " (no_vertical_channel: the horizontal components only)" if count == 2 else ""
            raise ModelError(f"the {what} error has {len(states)} states, {count} expected{reason}")
    scoped_equations = sorted(set(problem.approximation_scopes) & EQUATION_APPROXIMATIONS)
    if scoped_equations:
        raise ModelError(f"approximation {scoped_equations[0]!r} changes the perturbed equations and cannot be scoped ('in:')")
    unknown = [a for a in problem.approximations if a not in APPROXIMATIONS]
    if unknown:
        raise ModelError(f"unknown approximation(s) {', '.join(unknown)} (known: {', '.join(sorted(APPROXIMATIONS))})")
    navigation = set(declared_navigation_states(problem))
    missing = [str(s) for s in problem.state_order if s not in navigation and s not in problem.auxiliary_dynamics]
    if missing:
        raise ModelError(f"error state(s) {', '.join(missing)} have no equation")


def derive_error_equations(problem: NavigationProblem) -> ErrorEquations:
    """F, G, H of the declared error states, exact to first order except the declared approximations.

    Each approximation is applied in the order declared; the entries it
    changes become :class:`NeglectedTerm` records (the removed term =
    before - after, in parameter symbols).
    """
    check_problem(problem)
    problem, placeholders = _with_vertical_placeholders(problem)
    problem, frame_angle = _with_frame_angle_placeholder(problem)
    equation_flags: set[str] = set()
    stage = declared_stage(problem, primitive_stage(problem, equation_flags))
    finished = finish(stage, problem)
    neglected: list[NeglectedTerm] = []
    readable: list[str] = []
    for name in problem.approximations:
        before = stage
        if name in EQUATION_APPROXIMATIONS:  # never scoped (check_problem)
            equation_flags.add(name)
            stage = declared_stage(problem, primitive_stage(problem, equation_flags))
            for other in problem.approximations[: problem.approximations.index(name)]:
                if other not in EQUATION_APPROXIMATIONS:
                    stage = scoped(other, APPROXIMATIONS[other](stage, problem), stage, problem)
        else:
            stage = scoped(name, APPROXIMATIONS[name](stage, problem), stage, problem)
        after = finish(stage, problem)
        found = _differences(name, finished, after)
        neglected.extend(found)
        readable.extend(readable_term(getattr(before, t.matrix)[t.row, t.column] - getattr(stage, t.matrix)[t.row, t.column], problem) for t in found)
        finished = after
    if frame_angle:
        _refuse_frame_angle_dependence(finished, problem, frame_angle[0])
    return _without_states(
        ErrorEquations(
            F=finished.F,
            G=finished.G,
            H=finished.H,
            states=tuple(problem.state_order),
            noises=tuple(problem.noises),
            measurements=tuple(s for m in problem.measurements for s in m.symbols),
            neglected=tuple(neglected),
            readable=tuple(readable),
        ),
        (*placeholders, *frame_angle),
    )


def _with_frame_angle_placeholder(problem: NavigationProblem) -> tuple[NavigationProblem, tuple[sp.Symbol, ...]]:
    """A position with one more coordinate than its error (wander azimuth's chart: the frame's turn about the
    vertical, the wander-angle error with the longitude error) gets that frame angle as a placeholder state,
    after the position states; it is removed at the end (:func:`_refuse_frame_angle_dependence` first)."""
    e = problem.errors
    if problem.position.rows == len(e.position_states):
        return problem, ()
    angle = sp.Dummy("vertical_frame_angle_error", real=True)
    errors = replace(e, position_states=(*e.position_states, angle))
    order: list[sp.Symbol] = []
    for s in problem.state_order:
        order.append(s)
        if s == e.position_states[-1]:
            order.append(angle)
    return replace(problem, errors=errors, state_order=tuple(order)), (angle,)


def _refuse_frame_angle_dependence(equations: Stage, problem: NavigationProblem, angle: sp.Symbol) -> None:
    """The declared errors' rates and the measurements must not depend on the placeholder frame angle.

    The psi-angle, computed-frame velocity and metres position errors of the wander frame do not (their
    equations need no true wander angle: Benson 1975, Scherzinger & Reid 1994); anything else would be
    a derivation error, refused rather than dropped.
    """
    column = list(problem.state_order).index(angle)
    rows = [i for i in range(equations.F.rows) if i != column and equations.F[i, column] != 0]
    measured = [i for i in range(equations.H.rows) if equations.H[i, column] != 0]
    if rows or measured:
        names = [str(problem.state_order[i]) for i in rows] + [f"measurement row {i}" for i in measured]
        raise ModelError(
            f"the {problem.mechanization_name} error model depends on the frame angle about the vertical, which has no "
            f"error state ({', '.join(names)}): use the psi-angle, computed-frame velocity and metres position errors"
        )


def _with_vertical_placeholders(problem: NavigationProblem) -> tuple[NavigationProblem, tuple[sp.Symbol, ...]]:
    """Under ``no_vertical_channel`` the model declares horizontal velocity and position errors (2 each);
    the derivation runs with the vertical ones as placeholder states, removed at the end."""
    e = problem.errors
    if "no_vertical_channel" not in problem.approximations:
        return problem, ()
    velocity, height = sp.Dummy("vertical_velocity_error", real=True), sp.Dummy("vertical_position_error", real=True)
    errors = ErrorDefinition(e.attitude, e.attitude_states, e.velocity, (*e.velocity_states, velocity), e.position, (*e.position_states, height))
    order: list[sp.Symbol] = []
    for s in problem.state_order:
        order.append(s)
        if s == e.velocity_states[-1]:
            order.append(velocity)
        if s == e.position_states[-1]:
            order.append(height)
    return replace(problem, errors=errors, state_order=tuple(order)), (velocity, height)


def _without_states(equations: ErrorEquations, removed: Sequence[sp.Symbol]) -> ErrorEquations:
    """``equations`` without the ``removed`` states; a neglected term in a removed row or column gets index -1."""
    if not removed:
        return equations
    kept = [i for i, s in enumerate(equations.states) if s not in removed]
    new_index = {old: new for new, old in enumerate(kept)}

    def moved(term: NeglectedTerm) -> NeglectedTerm:
        row = new_index.get(term.row, -1) if term.matrix in ("F", "G") else term.row
        column = new_index.get(term.column, -1) if term.matrix in ("F", "H") else term.column
        return NeglectedTerm(term.approximation, term.matrix, row, column, term.term)

    return ErrorEquations(
        F=equations.F.extract(kept, kept),
        G=equations.G.extract(kept, list(range(equations.G.cols))) if equations.G.cols else sp.zeros(len(kept), 0),
        H=equations.H.extract(list(range(equations.H.rows)), kept) if equations.H.rows else sp.zeros(0, len(kept)),
        states=tuple(equations.states[i] for i in kept),
        noises=equations.noises,
        measurements=equations.measurements,
        neglected=tuple(moved(t) for t in equations.neglected),
        readable=equations.readable,
    )


def _differences(name: str, before: Stage, after: Stage) -> list[NeglectedTerm]:
    """The entries ``name`` changed, as NeglectedTerm records (term = before - after)."""
    out = []
    for label in ("F", "G", "H"):
        a, b = getattr(before, label), getattr(after, label)
        for i in range(a.rows):
            for j in range(a.cols):
                if a[i, j] != b[i, j]:
                    difference = simplify_entry(a[i, j] - b[i, j])
                    if difference != 0 and not _is_zero_function(difference):
                        out.append(NeglectedTerm(name, label, i, j, difference))
    return out


def _is_zero_function(expr: sp.Expr) -> bool:
    """Whether ``expr`` is identically zero, e.g. x/(R cos L + h cos L) - x/((R + h) cos L).

    A value at a fixed generic point (each symbol 0.2 + 0.0137 k, deterministic)
    that is not small decides quickly; otherwise rational functions are cancelled.
    """
    symbols = sorted(expr.free_symbols, key=str)
    point = {s: sp.Float(0.2 + 0.0137 * k) for k, s in enumerate(symbols)}
    value = expr.xreplace(point)
    scale = sum(abs(t.xreplace(point)) for t in sp.Add.make_args(expr))
    if value.is_number and scale.is_number and abs(float(value)) > 1e-9 * float(scale):
        return False
    return sp.cancel(sp.together(expr)) == 0
