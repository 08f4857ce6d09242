"""`modelgen verify MODEL --table FILE`: a user's own partial table, with automatic hints.

The table in tests/checks/data/enu_doppler18_user_table.yaml lists nine entries
of the built-in enu_doppler18 model, in a paper's arc-second units: five right,
one with a flipped sign, one missing the unit factor M, one put in the wrong
column, and one known difference explained by an annotation.
"""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
import yaml
from click.testing import CliRunner

from modelgen.checks.paper_check import verify
from modelgen.checks.paper_table import load_paper_table, paper_table_path
from modelgen.cli import main
from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path

DATA = Path(__file__).parent / "data"
USER_TABLE = DATA / "enu_doppler18_user_table.yaml"
SCHEMA = data_path() / "verify_table.schema.json"


@pytest.fixture(scope="module")
def enu_derived(derived_builtin):
    return derived_builtin("enu_doppler18")


@pytest.fixture(scope="module")
def user_result(enu_derived):
    return verify(enu_derived, USER_TABLE, complete=False)


def by_label(result):
    return {e.label: e for e in result.entries}


def test_only_the_listed_entries_are_compared_by_default(user_result):
    assert len(user_result.entries) == 9
    assert user_result.counts() == {"match": 5, "differ": 4, "paper_only": 0, "derived_only": 0}


def test_complete_also_reports_every_derived_nonzero_the_table_omits(enu_derived, user_result):
    complete = verify(enu_derived, USER_TABLE, complete=True)
    assert complete.counts()["derived_only"] > 50
    assert {e.label for e in user_result.entries} < {e.label for e in complete.entries}


def test_right_entries_match_in_the_tables_own_units(user_result):
    entries = by_label(user_result)
    for label in ("F(1,2)", "F(1,5)", "F(4,2)", "G(1,1)", "H(1,4)"):
        assert entries[label].status == "match", label


def test_each_mistake_is_unexplained_and_gets_its_hint(user_result):
    entries = by_label(user_result)
    assert {e.label for e in user_result.unexplained} == {"F(2,4)", "F(5,1)", "F(6,5)"}
    assert entries["F(2,4)"].hints == ("sign flip: the written entry is the derived one with the opposite sign",)
    assert entries["F(5,1)"].hints[0].startswith("unit factor: written = M x derived")
    assert entries["F(6,5)"].hints == ("misplaced entry: the written value is the derived F(6,4)",)


def test_an_annotated_difference_is_explained_and_carries_no_hint(user_result):
    entry = by_label(user_result)["F(4,5)"]
    assert (entry.status, entry.classification, entry.hints) == ("differ", "omitted_in_paper", ())


def test_hints_are_in_the_json_records_and_the_markdown(user_result):
    records = {f"{r['matrix']}({r['row']},{r['column']})": r for r in json.loads(user_result.to_json())["entries"]}
    assert records["F(6,5)"]["hints"] == ["misplaced entry: the written value is the derived F(6,4)"]
    assert "hints" not in records["F(1,2)"]
    assert "hint: sign flip" in user_result.to_markdown()


def test_cli_verify_table_prints_the_hints_and_exits_1(tmp_path):
    run = CliRunner().invoke(main, ["verify", "enu_doppler18", "--table", str(USER_TABLE), "--out", str(tmp_path / "r")])
    assert run.exit_code == 1, run.output
    assert "9 entries, 5 match, 4 differ, 0 paper_only, 0 derived_only" in run.output
    assert "    hint: misplaced entry: the written value is the derived F(6,4)" in run.output
    assert (tmp_path / "r" / "verification.json").is_file()


def test_cli_verify_table_exits_0_when_every_difference_is_annotated(tmp_path):
    data = yaml.safe_load(USER_TABLE.read_text(encoding="utf-8"))
    data["entries"] = [e for e in data["entries"] if (e["row"], e["col"]) not in {(2, 4), (5, 1), (6, 5)}]
    table = tmp_path / "fixed.yaml"
    table.write_text(yaml.safe_dump(data), encoding="utf-8")
    run = CliRunner().invoke(main, ["verify", "enu_doppler18", "--table", str(table), "--out", str(tmp_path / "r")])
    assert run.exit_code == 0, run.output
    assert "6 entries, 5 match, 1 differ" in run.output


def test_cli_verify_table_takes_the_model_from_the_tables_model_key(tmp_path):
    """`modelgen verify --table FILE` needs no MODEL: the table names it (`model: enu_doppler18`)."""
    named = CliRunner().invoke(main, ["verify", "--table", str(USER_TABLE), "--out", str(tmp_path / "a")])
    given = CliRunner().invoke(main, ["verify", "enu_doppler18", "--table", str(USER_TABLE), "--out", str(tmp_path / "b")])
    assert named.exit_code == given.exit_code == 1, named.output
    assert "model enu_doppler18 against enu_doppler18_user_table.yaml: 9 entries" in named.output
    assert (tmp_path / "a" / "verification.json").read_bytes() == (tmp_path / "b" / "verification.json").read_bytes()


def test_cli_verify_table_without_model_key_or_argument_asks_for_the_model(tmp_path):
    table = tmp_path / "anonymous.yaml"
    table.write_text('entries:\n  - {matrix: F, row: 1, col: 2, expression: "1"}\n', encoding="utf-8")
    run = CliRunner().invoke(main, ["verify", "--table", str(table), "--out", str(tmp_path / "r")])
    assert run.exit_code == 2
    assert run.output.strip() == (f"modelgen: error: {table}: the table has no 'model:' key: name the model "
                                  "(modelgen verify MODEL --table anonymous.yaml) or add 'model: <name>' to the table")
    assert not (tmp_path / "r").exists()


def test_cli_verify_table_naming_a_model_that_is_not_built_in_asks_for_its_file(tmp_path):
    """The model: key is a name, never a path: a table for a user's model needs that model's file as MODEL."""
    table = tmp_path / "mine.yaml"
    table.write_text('model: ../../etc/passwd\nentries:\n  - {matrix: F, row: 1, col: 2, expression: "1"}\n', encoding="utf-8")
    run = CliRunner().invoke(main, ["verify", "--table", str(table), "--out", str(tmp_path / "r")])
    assert run.exit_code == 2
    assert run.output.strip() == (f"modelgen: error: {table}: the table is written for model '../../etc/passwd', which is "
                                  "not a built-in model: give its file (modelgen verify MODEL.yaml --table mine.yaml)")


def test_a_table_for_another_model_is_refused(paper_model):
    with pytest.raises(ModelError, match="written for model 'enu_doppler18', not 'ned_doppler18'"):
        load_paper_table(USER_TABLE, paper_model)


def test_a_unit_for_a_state_the_model_lacks_is_refused(tmp_path, enu_derived):
    table = tmp_path / "t.yaml"
    table.write_text("state_units:\n  - {state: alpha, factor: M}\nentries: []\n", encoding="utf-8")
    with pytest.raises(ModelError, match="state_units names 'alpha', which is not one of the states of model 'enu_doppler18'"):
        load_paper_table(table, enu_derived.model)


@pytest.mark.parametrize("which", ["shipped", "user"])
def test_the_shipped_and_the_user_table_follow_the_json_schema(which):
    path = paper_table_path("ned_doppler18") if which == "shipped" else USER_TABLE  # found when run, not at collection
    schema = json.loads(SCHEMA.read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.Draft202012Validator(schema).validate(yaml.safe_load(Path(path).read_text(encoding="utf-8")))


@pytest.mark.parametrize(
    "table",
    [
        {"model": "enu_doppler18"},
        {"entries": [{"matrix": "P", "row": 1, "col": 1, "expression": "1"}]},
        {"entries": [{"matrix": "F", "row": 0, "col": 1, "expression": "1"}]},
        {"entries": [{"matrix": "F", "row": 1, "col": 1, "expression": "1", "reading": "2"}]},
        {"entries": [], "colour": "red"},
    ],
    ids=["no entries", "unknown matrix", "row 0", "reading without why", "unknown key"],
)
def test_the_json_schema_refuses_malformed_tables(table):
    schema = json.loads(SCHEMA.read_text(encoding="utf-8"))
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.Draft202012Validator(schema).validate(table)
