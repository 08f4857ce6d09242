"""The jobs hand derived models to each other; which model is the paper's comes from data."""

from __future__ import annotations

import ast

import pytest

from conftest import REPO
from modelgen import jobs
from modelgen.errors import ModelError


def test_a_model_is_derived_once_per_job_and_the_same_object_is_handed_out(monkeypatch, paper_derived):
    calls = []

    def counting(model):
        calls.append(str(model))
        return paper_derived

    monkeypatch.setattr(jobs, "load_and_derive", counting)
    models = jobs.DerivedModels()
    first = models.get("ned_doppler18")
    assert models.get("ned_doppler18") is first and calls == ["ned_doppler18"]


def test_a_model_the_caller_derived_is_not_derived_again(monkeypatch, paper_derived):
    monkeypatch.setattr(jobs, "load_and_derive", lambda model: pytest.fail(f"{model} derived again"))
    models = jobs.DerivedModels()
    models.add("ned_doppler18", paper_derived)
    assert models.get("ned_doppler18") is paper_derived


def test_generate_takes_a_derived_model_without_deriving_it_again(monkeypatch, tmp_path, paper_derived):
    monkeypatch.setattr(jobs, "load_and_derive", lambda model: pytest.fail(f"{model} derived again"))
    result = jobs.generate(paper_derived, tmp_path)
    assert result.derived is paper_derived and (tmp_path / "ned_doppler18" / "ned_doppler18.c").is_file()


def test_the_papers_model_is_the_one_its_table_names(tmp_path):
    from modelgen.checks.paper_table import CORE_PAPER_TABLE, paper_table_model
    from modelgen.fileio.datafiles import data_path

    assert paper_table_model(data_path(CORE_PAPER_TABLE)) == "ned_doppler18"
    table = tmp_path / "paper_999_table.yaml"
    table.write_text("model: my_model\n")
    assert paper_table_model(table) == "my_model"
    table.write_text("source: no model key\n")
    with pytest.raises(ModelError, match="needs 'model: <model name>'"):
        paper_table_model(table)


def _builtin_model_names() -> set[str]:
    return {p.stem for p in (REPO / "modelgen" / "models").glob("*.yaml")}


def test_no_code_compares_anything_with_a_built_in_models_name():
    """A model's role (the paper's model...) is data: no ``x == "ned_doppler18"`` in the package."""
    names = _builtin_model_names()
    found = []
    for path in (REPO / "modelgen").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Compare):
                operands = [node.left, *node.comparators]
                literals = {o.value for o in operands if isinstance(o, ast.Constant) and isinstance(o.value, str)}
                for o in operands:
                    if isinstance(o, (ast.Tuple, ast.List, ast.Set)):
                        literals |= {e.value for e in o.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)}
                if literals & names:
                    found.append(f"{path.relative_to(REPO)}:{node.lineno}")
    assert not found, found


def _profile_with_filter_constants(tmp_path, constants: dict) -> str:
    import yaml

    from modelgen.fileio.datafiles import data_path

    data = yaml.safe_load(data_path("profile_000.yaml").read_text(encoding="utf-8"))
    data["filter"]["parameters"] = constants
    path = tmp_path / "profile.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return str(path)


def test_a_misspelt_filter_constant_is_refused_by_name_with_the_close_match(tmp_path):
    path = _profile_with_filter_constants(tmp_path, {"doppler_noise_sigma_nort": 0.1})
    with pytest.raises(ModelError, match=r"'doppler_noise_sigma_nort' is not a parameter of model 'ned_doppler18' "
                                         r"\(did you mean 'doppler_noise_sigma_north'\?\)"):
        jobs.flight_scenario(path)


def test_filter_constants_the_model_has_are_kept_and_another_model_takes_only_matching_names(tmp_path):
    path = _profile_with_filter_constants(tmp_path, {"doppler_noise_sigma_north": 0.1})
    assert jobs.flight_scenario(path).filter.parameters == {"doppler_noise_sigma_north": 0.1}
    other = _profile_with_filter_constants(tmp_path, {"doppler_noise_sigma_nort": 0.1})
    assert jobs.flight_scenario(other, model="ned_inertial16").filter.model == "ned_inertial16"


def test_the_run_report_states_every_target_met_or_missed_and_shows_every_figure_with_its_caption():
    from pathlib import Path

    from modelgen.jobs import ReportSection, missed_targets, run_report

    section = ReportSection("Replay", "flown.", (
        {"quantity": "end error RMS", "reached": "3.5 m", "target": "<= 5.0 m", "met": True},
        {"quantity": "inside 3 sigma", "reached": "64 %", "target": ">= 90 %", "met": False},
        {"quantity": "wall time", "reached": "12 s", "target": "", "met": None}),
        (("replay/track.svg", "The track on a map."),))
    text = run_report("65 entries; 0 unexplained.", [], Path("generated"), [section],
                      paper_targets=({"quantity": "unexplained", "reached": "0", "target": "0", "met": True},))
    targets = text.split("## Targets\n", 1)[1].split("\n## ", 1)[0]
    assert "3 of 4 stated targets met, 1 missed." in targets  # the paper's, the code's (0 of 0 models), two here
    assert "| Replay | inside 3 sigma | 64 % | >= 90 % | **missed** |" in targets
    assert "| Replay | end error RMS | 3.5 m | <= 5.0 m | met |" in targets and "| Replay | wall time | 12 s |  |  |" in targets
    assert "![track](replay/track.svg)\n\nThe track on a map." in text
    assert missed_targets(text) == ["Replay: inside 3 sigma (64 %, target >= 90 %)"]
    assert "C elementwise dP (not bounded)" in text


@pytest.mark.compile
def test_the_conformance_table_shows_every_implementation_checked_beside_the_tolerance_that_bounds_it(tmp_path):
    from pathlib import Path

    from modelgen.jobs import ModelRun, conformance_section, generate, load_and_derive

    result = generate(load_and_derive("ned_inertial16"), tmp_path, with_check=True)
    section = conformance_section([ModelRun(result, list(result.checks))], Path("generated"))
    header, _, row = [line for line in section.text.splitlines() if line.startswith("|")]
    names = {"python": "Python", "c": "C", "cpp": "C++"}
    shown = [names[r.implementation] for r in result.checks]
    assert f"tolerance (bounds the {2 * len(shown)} scaled columns)" in header
    assert all(f"| {name} scaled dP | {name} scaled dx |" in header for name in shown)
    cells = dict(zip(*([c.strip() for c in line.strip().strip("|").split("|")] for line in (header, row))))
    tolerance = float(cells[f"tolerance (bounds the {2 * len(shown)} scaled columns)"])
    scaled = [float(v) for k, v in cells.items() if " scaled d" in k]
    # the verdict follows from the numbers shown: ok exactly when every scaled column is below the tolerance
    assert (cells["verdict"] == "ok") == all(v < tolerance for v in scaled) == result.passed
    assert section.targets[0]["met"] is result.passed
