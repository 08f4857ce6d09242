"""The README's model example works as documented, and so does its error message."""

import re

import pytest
from click.testing import CliRunner

from modelgen.cli import main

from conftest import REPO


def readme_model() -> str:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    return re.search(r"```yaml\n(.*?)```", text, re.S).group(1)


@pytest.mark.compile
def test_readme_example_generates_and_passes_the_compiled_check(tmp_path):
    path = tmp_path / "schuler_loop.yaml"
    path.write_text(readme_model())
    result = CliRunner().invoke(main, ["generate", str(path), "--out", str(tmp_path / "gen"), "--check"])
    assert result.exit_code == 0, result.output
    assert "check c" in result.output and "FAILED" not in result.output
    assert (tmp_path / "gen" / "schuler_loop" / "schuler_loop.c").is_file()


def test_readme_error_message_is_what_modelgen_prints(tmp_path):
    path = tmp_path / "schuler_loop.yaml"
    path.write_text(readme_model().replace("dV_n: g*phi_e + nabla", "dV_n: g*phi_e + nablaa"))
    result = CliRunner().invoke(main, ["generate", str(path), "--out", str(tmp_path / "gen")])
    assert result.exit_code == 2
    documented = re.search(r"modelgen: error: schuler_loop\.yaml:(\d+): (.*)", (REPO / "README.md").read_text()).groups()
    assert f"{path}:{documented[0]}: {documented[1]}" in result.output
    assert not (tmp_path / "gen").exists()


def test_readme_transform_example_builds_a_14_state_model(tmp_path):
    from modelgen.derive.symbolic import derive
    from modelgen.model.loading import load_model

    text = (REPO / "README.md").read_text(encoding="utf-8")
    example = re.findall(r"```yaml\n(.*?)```", text, re.S)[1]
    path = tmp_path / "reduced.yaml"
    path.write_text(example)
    derived = derive(load_model(path))
    assert derived.n_states == 14 and derived.model.state_names[-1] == "doppler_scale_factor"


def test_readme_test_command_is_what_ci_runs():
    """README's second command is the one .ci/run runs (CI runs what users are told to run)."""
    import re

    readme = (REPO / "README.md").read_text(encoding="utf-8")
    commands = re.findall(r"```sh\n(pip install [^\n]+)\n```", readme)
    assert len(commands) >= 2, commands
    assert commands[1] in (REPO / ".ci" / "run").read_text(encoding="utf-8")
    assert all("-c constraints.txt" in c for c in commands[:2])


@pytest.mark.compile
def test_readme_vector_model_generates_and_passes_the_compiled_check(tmp_path):
    """The README's vector model (found by its name) loads, generates and passes --check."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    example = next(block for block in re.findall(r"```yaml\n(.*?)```", text, re.S) if block.startswith("model: vector_ins"))
    path = tmp_path / "vector_ins.yaml"
    path.write_text(example)
    result = CliRunner().invoke(main, ["generate", str(path), "--out", str(tmp_path / "gen"), "--check"])
    assert result.exit_code == 0, result.output
    assert "check c" in result.output and "FAILED" not in result.output


def test_readme_documents_every_navigation_library_function_and_constant():
    from modelgen.model.navlib import NAVLIB_CONSTANTS, NAVLIB_FUNCTIONS

    text = (REPO / "README.md").read_text(encoding="utf-8")
    section = text.split("\n## Navigation library\n", 1)[1].split("\n## ", 1)[0]
    missing = [name for name in (*NAVLIB_FUNCTIONS, *NAVLIB_CONSTANTS) if f"`{name}" not in section and f"`{name}(" not in section and f" `{name}" not in section]
    assert missing == []
