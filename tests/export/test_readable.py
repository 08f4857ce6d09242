"""modelgen.export.readable: entries printed factored for people, the same function, the same text every time."""

from __future__ import annotations

import sympy as sp

from modelgen.export.readable import nonzero_entries, readable

L, h, v_E, v_N, v_U, R_N, w = sp.symbols("L h v_E v_N v_U R_N omega_ie", real=True)


def test_an_expanded_denominator_is_printed_as_the_power_of_its_sum():
    assert sp.sstr(readable(-v_E / (R_N**2 + 2 * R_N * h + h**2))) == "-v_E/(R_N + h)**2"


def test_common_factors_are_pulled_out_of_a_sum():
    entry = sp.expand(-v_E * v_N * sp.tan(L) / (R_N + h) ** 2 + v_E * v_U / (R_N + h) ** 2)
    assert sp.sstr(readable(entry)) == "-v_E*(v_N*tan(L) - v_U)/(R_N + h)**2"
    assert sp.sstr(readable(-2 * w * sp.cos(L) - 2 * v_E / (R_N + h))) == "-2*(omega_ie*cos(L) + v_E/(R_N + h))"


def test_every_readable_entry_of_a_built_in_model_is_the_same_function(enu_derived):
    for name in ("F", "G", "H", "Q", "R"):
        for i, j, entry in nonzero_entries(getattr(enu_derived, name)):
            shown = readable(entry)
            assert sp.expand(sp.together(shown - entry)) == 0, f"{name}({i},{j})"
            assert "R_N**2" not in sp.sstr(shown) and "R_M**2" not in sp.sstr(shown), f"{name}({i},{j})"


def test_numerators_over_one_denominator_are_combined_and_cancel():
    entry = -(R_N * v_N * sp.tan(L) + h * v_N * sp.tan(L)) / ((R_N + h) * (w + h)) - v_U / (R_N + h)
    assert sp.sstr(readable(sp.expand(entry))) == "-(v_N*tan(L)/(h + omega_ie) + v_U/(R_N + h))"


def test_atoms_stay_as_they_are_and_the_output_is_deterministic():
    assert readable(sp.Integer(1)) == 1 and readable(L) == L
    entry = sp.expand(v_N / (R_N + h) ** 2 + w * sp.sin(L))
    assert sp.sstr(readable(entry)) == sp.sstr(readable(sp.sympify(sp.sstr(entry), locals={s.name: s for s in entry.free_symbols})))


def test_nonzero_entries_are_one_based_row_by_row():
    assert nonzero_entries(sp.Matrix([[0, L], [h, 0]])) == [(1, 2, L), (2, 1, h)]
