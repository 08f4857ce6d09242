"""The paper check finds the paper's known differences, and nothing unexplained."""

from __future__ import annotations

import json

import pytest
import sympy as sp
from click.testing import CliRunner

from modelgen.cli import main
from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel
from modelgen.checks.paper_table import CLASSIFICATIONS, load_paper_table, paper_table_path
from modelgen.checks.paper_check import RECORD_FIELDS, UNEXPLAINED, verify, write_verification_report

# (matrix, row, col) -> (status, classification): the differences a human
# judged in modelgen/data/paper_000_table.yaml, found by the comparison.
KNOWN_DIFFERENCES = {
    ("F", 3, 5): ("differ", "paper_typo"),  # +M/R tg(phi) printed, eq. (1) has the minus sign
    ("F", 4, 4): ("derived_only", "omitted_in_paper"),  # V_d/R
    ("F", 4, 5): ("derived_only", "omitted_in_paper"),  # -(2 w sin + 2 V_e tg/R)
    ("F", 5, 2): ("paper_only", "paper_typo"),  # -a_n/M printed in the beta column
    ("F", 5, 3): ("derived_only", "paper_typo"),  # ... where gamma's column is meant
    ("F", 5, 6): ("differ", "unit_inconsistency"),  # printed without 1/M
}


def rebuild(model: ErrorModel, **dynamics: str | sp.Expr) -> ErrorModel:
    """A copy of ``model`` built with ErrorModel.build, some equations replaced."""
    equations = {s.name: model.dynamics[s.name] for s in model.states}
    equations.update(dynamics)
    return ErrorModel.build(
        name=model.name,
        states=model.states,
        noises=model.noises,
        parameters=model.parameters,
        dynamics=equations,
        measurements=model.measurements,
    )


@pytest.fixture(scope="module")
def table():
    return load_paper_table(paper_table_path("ned_doppler18"))


@pytest.fixture(scope="module")
def result(paper_derived):
    return verify(paper_derived)


def test_table_file_loads_and_every_index_is_inside_the_papers_matrix_sizes(table):
    sizes = {"F": (18, 18), "G": (18, 6), "H": (2, 18)}
    assert dict(table.shape) == sizes
    assert len(table.entries) == 62  # 52 F + 6 G + 4 H as printed
    for entry in (*table.entries, *table.equation_1_entries):
        rows, cols = sizes[entry.matrix]
        assert 1 <= entry.row <= rows and 1 <= entry.col <= cols, entry.label
    assert len({e.key for e in table.entries}) == len(table.entries)


def test_references_between_printed_entries_are_resolved(table):
    by_key = {e.key: e for e in table.entries}
    assert by_key[("F", 2, 1)].expression == "-F(1,2)"
    assert sp.simplify(by_key[("F", 2, 1)].value + by_key[("F", 1, 2)].value) == 0
    assert by_key[("F", 6, 4)].value == by_key[("F", 1, 5)].value
    assert not any(s.name.startswith("ref_") for e in table.entries for s in e.value.free_symbols)


def test_garbled_prints_carry_a_reading_and_a_reason(table):
    readings = {e.label: (e.expression, e.reading) for e in table.entries if e.reading}
    assert readings == {
        "F(11,11)": ("-mu_xx", "-mu_eps_x"),
        "F(12,12)": ("-mu_yy", "-mu_eps_y"),
        "F(13,13)": ("-mu_xx", "-mu_eps_z"),
    }
    assert all(e.why for e in table.entries if e.reading)


def test_unit_factors_are_arcseconds_for_angles_and_drifts_and_one_otherwise(table):
    M = table.unit_symbol
    factors = {u.quantity: u.factor for u in table.state_units}
    assert [q for q, f in factors.items() if f == M] == [
        "alpha", "beta", "gamma", "dphi", "dlambda", "eps_c_x", "eps_c_y", "eps_c_z", "eps_r_x", "eps_r_y", "eps_r_z"
    ]
    assert all(f == 1 for q, f in factors.items() if f != M)
    assert sp.simplify(table.unit_value - 180 * 3600 / sp.pi) == 0


def test_every_paper_entry_is_accounted_for(result, table):
    compared = {(e.matrix, e.row, e.column): e for e in result.entries}
    for entry in table.entries:
        record = compared[entry.key]
        assert record.printed == entry.printed
        assert record.status in ("match", "differ", "paper_only"), entry.label
    assert sum(result.counts().values()) == len(result.entries) == 65


def test_known_differences_are_found_with_their_classifications(result):
    found = {(e.matrix, e.row, e.column): (e.status, e.classification) for e in result.differences}
    assert found == KNOWN_DIFFERENCES
    assert all(e.reason for e in result.differences)
    assert {c for _, c in found.values()} <= set(CLASSIFICATIONS)


def test_the_paper_model_has_no_unexplained_difference_and_no_stale_annotation(result):
    assert [e.label for e in result.unexplained] == []
    assert result.unused_annotations == ()


def test_equation_1_cross_check_reports_the_factor_two_on_ve_tan_over_r(result):
    checks = {e.label: e for e in result.equation_1_checks}
    assert checks["F(4,4)"].status == "match"
    assert checks["F(5,3)"].status == "match"  # the table's F(5,2) really is gamma's coefficient
    assert (checks["F(4,5)"].status, checks["F(4,5)"].classification) == ("differ", "model_difference")


def test_a_flipped_sign_in_the_model_is_an_unexplained_difference(paper_model):
    altered = rebuild(paper_model, latitude_error="-dV_n/R")
    result = verify(derive(altered))
    unexplained = [(e.label, e.status) for e in result.unexplained]
    assert unexplained == [("F(6,4)", "differ")]
    assert result.counts()["differ"] == 3


def test_a_dropped_term_is_an_unexplained_paper_only_entry(paper_model):
    altered = rebuild(paper_model, longitude_error="dV_e/R*sec(phi)")
    labels = {(e.label, e.status, e.classification) for e in verify(derive(altered)).unexplained}
    assert labels == {("F(7,6)", "paper_only", UNEXPLAINED)}


def test_an_equivalent_trigonometric_form_still_matches(paper_model):
    heading = str(paper_model.dynamics["heading_error"])
    assert "sec(phi)**2" in heading
    altered = rebuild(
        paper_model,
        longitude_error="dV_e/(R*cos(phi)) + V_e*sin(phi)/(R*cos(phi)**2)*dphi",
        heading_error=heading.replace("sec(phi)**2", "(1 + tan(phi)**2)"),
    )
    result = verify(derive(altered))
    statuses = {e.label: e.status for e in result.entries}
    assert statuses["F(7,5)"] == statuses["F(7,6)"] == statuses["F(3,6)"] == "match"
    assert result.unexplained == []


def test_a_model_the_table_does_not_describe_is_refused(paper_model):
    inertial = derive(
        ErrorModel.build(
            name="ned_doppler18",
            states=paper_model.states[:16],
            noises=paper_model.noises,
            parameters=paper_model.parameters,
            dynamics={s.name: paper_model.dynamics[s.name] for s in paper_model.states[:16]},
        )
    )
    with pytest.raises(ModelError, match="table's states"):
        verify(inertial)


def test_a_garbled_print_without_a_reading_is_refused(tmp_path):
    text = paper_table_path("ned_doppler18").read_text(encoding="utf-8")
    broken = text.replace('    reading: "-mu_eps_y"\n    why: "As F(11,11): epsilon lost in OCR; row 12 is eps_r_y (eq. (3))."\n', "")
    assert broken != text
    path = tmp_path / "paper_000_table.yaml"
    path.write_text(broken, encoding="utf-8")
    with pytest.raises(ModelError, match=r"entries\[\d+\] \(F\(12,12\)\).*mu_yy.*reading"):
        load_paper_table(path)


def test_an_index_outside_the_matrix_is_refused(tmp_path):
    text = paper_table_path("ned_doppler18").read_text(encoding="utf-8")
    path = tmp_path / "paper_000_table.yaml"
    path.write_text(text.replace("{matrix: F, row: 7, col: 5,", "{matrix: F, row: 7, col: 19,"), encoding="utf-8")
    with pytest.raises(ModelError, match="col 19 is outside 1..18"):
        load_paper_table(path)


def test_json_records_have_the_documented_fields(result, tmp_path):
    _, data_path = write_verification_report(result, tmp_path)
    data = json.loads(data_path.read_text(encoding="utf-8"))
    assert set(data) == {"summary", "record_fields", "entries", "equation_1_checks", "units", "paper_inconsistencies"}
    assert data["record_fields"] == list(RECORD_FIELDS)
    for record in (*data["entries"], *data["equation_1_checks"]):
        assert set(record) == set(RECORD_FIELDS)
        assert record["status"] in ("match", "differ", "paper_only", "derived_only")
    f35 = next(r for r in data["entries"] if (r["matrix"], r["row"], r["column"]) == ("F", 3, 5))
    assert (f35["paper_expression"], f35["derived_expression"]) == ("M*tan(phi)/R", "-M*tan(phi)/R")
    assert data["summary"]["counts"] == {"match": 59, "differ": 2, "paper_only": 1, "derived_only": 3}
    assert data["summary"]["unexplained"] == 0
    assert any("20 names" in text for text in data["paper_inconsistencies"])


def test_report_is_byte_identical_run_to_run_and_leaves_no_temporary_files(paper_model, tmp_path):
    first = write_verification_report(verify(derive(paper_model)), tmp_path / "a")
    second = write_verification_report(verify(derive(paper_model)), tmp_path / "b")
    for one, two in zip(first, second):
        assert one.read_bytes() == two.read_bytes()
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["verification.json", "verification.md"]
    markdown = first[0].read_text(encoding="utf-8")
    assert "| F(5,6) | differ | unit_inconsistency |" in markdown
    assert "## The paper's own inconsistencies" in markdown


def test_cli_verify_writes_the_report_and_prints_each_difference(tmp_path):
    out = tmp_path / "report"
    run = CliRunner().invoke(main, ["verify", "ned_doppler18", "--out", str(out)])
    assert run.exit_code == 0, run.output
    assert "59 match, 2 differ, 1 paper_only, 3 derived_only" in run.output
    assert "F(3,5) differ: paper_typo" in run.output
    assert (out / "verification.md").is_file() and (out / "verification.json").is_file()


def test_cli_verify_on_a_model_without_paper_table_says_so_and_succeeds(tmp_path):
    model_file = tmp_path / "tiny.yaml"
    model_file.write_text(
        "model: tiny\nparameters:\n  - {name: rate, symbol: mu, value: 0.5}\n"
        "states:\n  - {name: drift, symbol: d}\ndynamics:\n  d: -mu*d\n",
        encoding="utf-8",
    )
    run = CliRunner().invoke(main, ["verify", str(model_file), "--out", str(tmp_path / "r")])
    assert run.exit_code == 0, run.output
    assert "no paper table" in run.output
    assert not (tmp_path / "r").exists()


def test_verify_refuses_a_model_without_paper_table():
    from modelgen.model.declaration import Parameter, State

    tiny = ErrorModel.build(
        name="tiny",
        states=[State(name="drift", symbol="d")],
        noises=[],
        parameters=[Parameter(name="rate", symbol="mu", value=0.5)],
        dynamics={"d": "-mu*d"},
    )
    with pytest.raises(ModelError, match="model 'tiny': no paper table"):
        verify(derive(tiny))
