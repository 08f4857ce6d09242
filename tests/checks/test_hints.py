"""modelgen.checks.hints: each automatic hint fires on its own mistake, and only on it."""

from __future__ import annotations

import sympy as sp

from modelgen.checks.hints import (
    ARCSECONDS_PER_RADIAN,
    HINT_KINDS,
    difference_hints,
    placement,
    same,
    sign_flip,
    term_differences,
    unit_factor,
)

L, h, v_E, v_N, R_M, R_N, w = sp.symbols("L h v_E v_N R_M R_N omega_ie", real=True)
ENTRY = w * sp.sin(L) + v_E * sp.tan(L) / (R_N + h)


def kinds(hints):
    return [hint.kind for hint in hints]


def test_same_recognises_a_trigonometric_identity_and_rejects_a_different_function():
    assert same(1 + sp.tan(L) ** 2, sp.sec(L) ** 2)
    assert not same(sp.tan(L), sp.sin(L))


def test_a_sign_flip_is_named_and_an_equal_entry_gets_no_sign_hint():
    assert sign_flip(-ENTRY, ENTRY).kind == "sign_flip"
    assert sign_flip(ENTRY, ENTRY) is None
    assert kinds(difference_hints(-ENTRY, ENTRY)) == ["sign_flip"]


def test_a_missing_arcsecond_factor_is_named_with_its_direction():
    hint = unit_factor(ENTRY, ENTRY * ARCSECONDS_PER_RADIAN)
    assert hint is not None and hint.text.startswith("unit factor: written = 1/M x derived")
    hint = unit_factor(ENTRY * 180 / sp.pi, ENTRY)
    assert hint is not None and hint.text.startswith("unit factor: written = 180/pi x derived")


def test_a_unit_factor_with_a_flipped_sign_says_both():
    hint = unit_factor(-3600 * ENTRY, ENTRY)
    assert hint is not None and "3600" in hint.text and "sign is flipped" in hint.text


def test_a_ratio_that_is_not_constant_is_no_unit_factor():
    assert unit_factor(ENTRY * L, ENTRY) is None
    assert unit_factor(2 * ENTRY, ENTRY) is None  # 2 is no unit factor


def test_transposed_indices_and_a_misplaced_entry_are_found():
    entries = {("F", 1, 2): ENTRY, ("F", 2, 1): -ENTRY, ("F", 1, 5): 1 / (R_M + h), ("F", 3, 2): v_N / (R_M + h)}
    assert kinds(placement(-ENTRY, ("F", 1, 2), entries)) == ["transposed"]
    hints = placement(1 / (R_M + h), ("F", 1, 4), entries)
    assert [h.text for h in hints] == ["misplaced entry: the written value is the derived F(1,5)"]
    hints = placement(v_N / (R_M + h), ("F", 7, 2), entries)
    assert [h.text for h in hints] == ["misplaced entry: the written value is the derived F(3,2)"]
    assert placement(v_N * h, ("F", 7, 2), entries) == []


def test_a_term_missing_from_a_sum_is_named():
    hints = term_differences(w * sp.sin(L), ENTRY)
    assert kinds(hints) == ["missing_term"]
    assert "v_E*tan(L)/(R_N + h)" in hints[0].text


def test_an_extra_term_and_a_flipped_term_are_named():
    assert kinds(term_differences(ENTRY + v_N / R_M, ENTRY)) == ["extra_term"]
    hints = term_differences(w * sp.sin(L) - v_E * sp.tan(L) / (R_N + h), ENTRY)
    assert kinds(hints) == ["term_sign"] and "v_E*tan(L)/(R_N + h)" in hints[0].text


def test_an_unrelated_difference_gets_no_hint():
    assert difference_hints(v_N * sp.cos(L), ENTRY, ("F", 1, 2), {("F", 1, 2): ENTRY}) == ()


def test_hints_are_deterministic_and_ordered_by_kind():
    first = difference_hints(-ENTRY, ENTRY, ("F", 2, 1), {("F", 1, 2): -ENTRY, ("F", 2, 1): ENTRY})
    second = difference_hints(-ENTRY, ENTRY, ("F", 2, 1), {("F", 1, 2): -ENTRY, ("F", 2, 1): ENTRY})
    assert first == second
    assert kinds(first) == ["sign_flip", "transposed"]
    assert [HINT_KINDS.index(k) for k in kinds(first)] == sorted(HINT_KINDS.index(k) for k in kinds(first))
