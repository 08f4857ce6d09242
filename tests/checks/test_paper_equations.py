"""The paper's printed eqs. (1)-(6) against derived error models: differences found by comparison, classified by rule."""

from __future__ import annotations

import json

import pytest
import sympy as sp

from modelgen.checks import paper_equations as pe
from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path


@pytest.fixture(scope="module")
def equations(paper_model):
    return pe.load_paper_equations(data_path(pe.CORE_PAPER_EQUATIONS), paper_model)


@pytest.fixture(scope="module")
def printed(equations, paper_model):
    return pe.paper_matrices(equations, paper_model)


def matrices(derived) -> dict[str, sp.Matrix]:
    return {m: getattr(derived, m).copy() for m in pe.MATRICES}


def test_transcription_gives_every_state_one_equation_and_the_printed_measurements(equations, paper_model):
    assert [e.target for e in equations.dynamics] == [s.symbol for s in paper_model.states]
    assert [e.target for e in equations.measurements] == ["Z_n", "Z_e"]
    assert equations.twin == "ned_doppler18_twin"
    assert all(t.printed for e in equations.dynamics for t in e.terms)


def test_printed_equations_against_the_hand_model_differ_only_in_the_transport_rate_factor(equations, paper_model, paper_derived):
    """The hand model keeps the first-principles factor 2 on V_e tan(phi)/R; the comparison must find exactly that."""
    result = pe.compare_equations(equations, paper_model, matrices(paper_derived))
    assert [(d.label, d.classification) for d in result.differences] == [("F(4,5)", "physics")]
    (d,) = result.differences
    assert d.rule.startswith("rule 3")
    assert sp.simplify(sp.sympify(d.difference) + sp.sympify("V_e*tan(phi)/R")) == 0
    # 83.3 m/s east at 30 N: V_e tan(phi)/R = 7.5e-6 1/s
    assert d.magnitude == pytest.approx(83.333333 * 0.57735027 / 6378137.0, rel=1e-6)
    assert result.compared == 70  # 64 entries of F, G, H and the 6 noise densities of eq. (5)


def test_a_negated_sensor_column_is_a_convention(equations, paper_model, paper_derived):
    derived = matrices(paper_derived)
    drift = paper_model.state_index("eps_c_y")
    for i in range(derived["F"].shape[0]):
        derived["F"][i, drift] = -derived["F"][i, drift]
    result = pe.compare_equations(equations, paper_model, derived)
    flipped = [d for d in result.differences if d.column == drift + 1]
    assert len(flipped) == 3 and {d.classification for d in flipped} == {"convention"}


def test_a_negated_navigation_column_is_not_a_convention(equations, paper_model, paper_derived):
    derived = matrices(paper_derived)
    gamma = paper_model.state_index("gamma")
    for i in range(derived["F"].shape[0]):
        derived["F"][i, gamma] = -derived["F"][i, gamma]
    result = pe.compare_equations(equations, paper_model, derived)
    assert {d.classification for d in result.differences if d.column == gamma + 1} != {"convention"}


def test_a_small_term_the_paper_lacks_is_an_omitted_term_and_a_large_one_physics(equations, paper_model, paper_derived):
    derived = matrices(paper_derived)
    i, j = paper_model.state_index("dphi"), paper_model.state_index("dV_n")
    V_d, V_e, R = sp.symbols("V_d V_e R", real=True)
    derived["F"][i, j] += V_d / R**2  # zero in the paper's level flight (V_d = 0)
    k = paper_model.state_index("dlambda")
    derived["F"][k, j] += V_e / R  # as large as the entry's own size: not small
    result = pe.compare_equations(equations, paper_model, derived)
    by_label = {d.label: d for d in result.differences}
    assert by_label[f"F({i + 1},{j + 1})"].classification == "omitted term"
    assert by_label[f"F({k + 1},{j + 1})"].classification == "physics"
    assert by_label[f"F({k + 1},{j + 1})"].rule.startswith("rule 5")


def test_a_printed_term_with_another_factor_is_a_typo(equations, paper_model, paper_derived):
    derived = matrices(paper_derived)
    i, j = paper_model.state_index("dlambda"), paper_model.state_index("dphi")
    derived["F"][i, j] = 3 * derived["F"][i, j]
    result = pe.compare_equations(equations, paper_model, derived)
    by_label = {d.label: d for d in result.differences}
    assert by_label[f"F({i + 1},{j + 1})"].classification == "typo"


def test_report_files_list_every_difference_with_its_classification(equations, paper_model, paper_derived, tmp_path):
    result = pe.compare_equations(equations, paper_model, matrices(paper_derived))
    markdown, data = pe.write_paper_equations_report(result, tmp_path)
    record = json.loads(data.read_text())
    assert record["summary"]["differences"] == 1
    assert set(record["differences"][0]) == set(pe.RECORD_FIELDS)
    assert "F(4,5)" in markdown.read_text() and "physics" in markdown.read_text()
    assert markdown.read_text() == result.to_markdown()  # byte-stable


def test_a_transcribed_term_with_an_unknown_symbol_is_refused(paper_model, tmp_path):
    text = data_path(pe.CORE_PAPER_EQUATIONS).read_text().replace('coefficient: "V_n/R"', 'coefficient: "V_x/R"', 1)
    bad = tmp_path / "paper_bad_equations.yaml"
    bad.write_text(text)
    with pytest.raises(ModelError, match=r"paper_bad_equations\.yaml:\d+: equations\[0\]\.terms\[2\]\.coefficient: unknown symbol\(s\) V_x"):
        pe.load_paper_equations(bad, paper_model)


def test_a_state_without_an_equation_is_refused(paper_model, tmp_path):
    lines = data_path(pe.CORE_PAPER_EQUATIONS).read_text().splitlines()
    kept = [line for line in lines if "state: dV_de" not in line]
    bad = tmp_path / "paper_bad_equations.yaml"
    bad.write_text("\n".join(kept) + "\n")
    with pytest.raises(ModelError, match=r"paper_bad_equations\.yaml:\d+: equations: every state needs exactly one equation \(missing: dV_de"):
        pe.load_paper_equations(bad, paper_model)


def test_the_paper_against_its_twin_finds_the_transport_rate_factor_and_the_drift_sign_convention(derived_builtin):
    """The first-principles check itself: eqs. (1)-(6) against the error model derived under the paper's assumptions."""
    result = pe.paper_equations_check(derived_builtin("ned_doppler18_twin"))
    by_class = {}
    for d in result.differences:
        by_class.setdefault(d.classification, []).append(d)
    assert sorted(by_class) == ["convention", "physics"]
    (physics,) = by_class["physics"]
    assert (physics.label, physics.row_quantity, physics.column_quantity, physics.equation) == ("F(4,5)", "dV_n", "dV_e", 1)
    assert physics.rule.startswith("rule 3")
    conventions = by_class["convention"]
    assert len(conventions) == 18 and {d.row for d in conventions} == {1, 2, 3}
    assert {d.column_quantity for d in conventions} == {f"eps_{k}_{a}" for k in "cr" for a in "xyz"}
    assert result.compared == 70 and result.scenario == "the check scenario of ned_doppler18_twin"


def test_verify_shows_the_first_principles_check_after_the_table_check_and_writes_its_files(tmp_path):
    from click.testing import CliRunner

    from modelgen.cli import main

    result = CliRunner().invoke(main, ["verify", "ned_doppler18", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    table, first = result.output.index("against paper_000_table.yaml"), result.output.index("the paper from first principles")
    assert table < first
    assert "F(4,5) (dV_n, dV_e), eq. (1): physics" in result.output and "18 entries" in result.output
    assert json.loads((tmp_path / "paper_equations.json").read_text())["summary"]["differences"] == 19
    assert (tmp_path / "verification.json").is_file()


def test_a_noise_density_printed_without_its_factor_two_is_found(equations, paper_model, paper_derived):
    derived = matrices(paper_derived)
    derived["Q"][0, 0] = derived["Q"][0, 0] / 2  # as if the paper's 2 mu sigma^2 were derived as mu sigma^2
    result = pe.compare_equations(equations, paper_model, derived)
    (d,) = [d for d in result.differences if d.matrix == "Q"]
    assert (d.label, d.row_quantity, d.equation, d.classification) == ("Q(1,1)", "w_eps_x", 5, "typo")
