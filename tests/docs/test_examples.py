"""Every code example of the documentation (and of the README's tour) runs.

* shell blocks: each ``modelgen`` command runs (click's CliRunner, in a folder
  holding the files the pages name) and exits 0, or with the error the page
  shows under it.  Not run: installation lines (``pip``, ``sudo apt-get``:
  the README's commands are CI's own, tests/test_readme.py) and the lines that
  start or use a dask cluster (``dask ...``, ``--scheduler``: tests/test_cluster.py
  runs a real scheduler and worker through the same options).  Commands that
  compile C are in the ``compile`` tier, those that fly or run the main job's
  analyses in the ``flight`` tier.
* Python blocks run (the simulation's in the ``flight`` tier);
* YAML blocks: a model file loads (and, with a check scenario, passes
  ``generate --check``, in the ``compile`` tier), a study file passes the
  study checks, a verify table is the one the tests use, and a fragment is part
  of a shipped file;
* the C usage example compiles against the generated header;
* a ``$ modelgen ...`` listing prints what the page shows.
"""

from __future__ import annotations

import ast
import re
import shlex
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from docs.pages import DOCS, REPO, Block, blocks, yaml_block

SLOW = {"generate": "compile", "embedded": "compile", "simulate": "flight", "replay": "flight", "trade": "flight",
        "covariance": "flight", "run": "flight"}
SKIPPED_WORDS = ("pip", "sudo", "dask")


def shell_commands() -> list[tuple[Block, str, str | None]]:
    """(block, command, documented error) for every modelgen command of the shell blocks."""
    found = []
    for block in blocks("sh"):
        lines = block.text.splitlines()
        for k, line in enumerate(lines):
            command = line.split("  #")[0].split(" # ")[0].strip()
            if not command or command.startswith("#") or command.split()[0] in SKIPPED_WORDS or "--scheduler" in command:
                continue
            assert command.startswith("modelgen "), f"{block.where}: a shell example that is not a modelgen command: {line}"
            error = lines[k + 1].lstrip("# ") if k + 1 < len(lines) and lines[k + 1].startswith("# modelgen: error:") else None
            found.append((block, command, error))
    return found


def _marks(command: str) -> list:
    words = command.split()
    tier = SLOW.get(words[1]) if "--check" in words or words[1] != "generate" else None
    return [getattr(pytest.mark, tier)] if tier else []


def _example_folder(tmp_path: Path) -> Path:
    """A folder holding the files the pages' commands name: the README's model and the verify table."""
    from docs.pages import page_text

    model = re.search(r"```yaml\n(model: schuler_loop.*?)```", page_text("model-language.md"), re.S).group(1)
    (tmp_path / "schuler_loop.yaml").write_text(model, encoding="utf-8")
    shutil.copy(REPO / "tests" / "checks" / "data" / "enu_doppler18_user_table.yaml", tmp_path)
    return tmp_path


@pytest.mark.parametrize(
    ("block", "command", "error"),
    [pytest.param(b, c, e, marks=_marks(c), id=f"{b.where}:{c}") for b, c, e in shell_commands()],
)
def test_shell_example_runs(block, command, error, tmp_path, monkeypatch):
    from modelgen.cli import main

    monkeypatch.chdir(_example_folder(tmp_path))
    result = CliRunner().invoke(main, shlex.split(command)[1:], catch_exceptions=False)
    if error is None:
        assert result.exit_code == 0, f"{block.where}: {command}\n{result.output[-3000:]}"
    else:
        assert result.exit_code == 2 and _shown_in(error.rstrip(". "), result.output.replace("\n", " ")), result.output


def _shown_in(documented: str, output: str) -> bool:
    """Whether the documented message is in the output, ``...`` in it standing for any text (a path, say)."""
    return re.search(".*?".join(re.escape(piece.strip()) for piece in documented.split("...")), output) is not None


def test_an_ellipsis_in_a_documented_error_stands_for_any_text_and_nothing_else_does():
    output = "modelgen: error: /any/where/model.yaml:22: model 'm' cannot fly this profile"
    assert _shown_in("modelgen: error: .../model.yaml:22: model 'm' cannot fly", output)
    assert not _shown_in("modelgen: error: .../model.yaml:23: model 'm' cannot fly", output)
    assert not _shown_in("modelgen: error: model 'm' cannot fly", output)


def test_the_verify_listing_is_what_modelgen_prints(tmp_path, monkeypatch):
    from modelgen.cli import main

    (listing,) = [b for b in blocks("text") if b.text.startswith("$ modelgen verify")]
    command, *shown = listing.text.rstrip("\n").splitlines()
    monkeypatch.chdir(_example_folder(tmp_path))
    result = CliRunner().invoke(main, shlex.split(command[2:])[1:])
    assert result.exit_code == 1
    assert [line for line in result.output.splitlines() if not line.startswith("wrote ")] == \
        [line for line in shown if not line.startswith("wrote ")]


def _python_marks(block: Block) -> list:
    return [pytest.mark.flight] if "fly_modes" in block.text else []


@pytest.mark.parametrize("block", [pytest.param(b, marks=_python_marks(b), id=b.where) for b in blocks("python")
                                   if b.page.name != "python-api.md"])  # that one: tests/test_api.py, with its results
def test_python_example_runs(block, tmp_path, monkeypatch):
    monkeypatch.chdir(_example_folder(tmp_path))
    (tmp_path / "my_table.yaml").write_text(yaml_block("verifying-a-paper.md", "model: enu_doppler18"), encoding="utf-8")
    namespace: dict = {"__name__": "__main__"}
    exec(compile(ast.parse(block.text), block.where, "exec"), namespace)


def _shipped_yaml() -> list:
    files = [*(REPO / "modelgen" / "models").glob("*.yaml"), *(REPO / "modelgen" / "data").rglob("*.yaml"),
             *(REPO / "modelgen" / "navigator" / "models").glob("*.yaml")]
    return [yaml.safe_load(path.read_text(encoding="utf-8")) for path in files]


def _part_of(fragment, whole) -> bool:
    """``fragment`` is found in ``whole``: its keys with parts of their values, its items each in an item, or equal."""
    if isinstance(fragment, dict):
        if isinstance(whole, dict) and all(k in whole and _part_of(v, whole[k]) for k, v in fragment.items()):
            return True
        return isinstance(whole, (dict, list)) and any(_part_of(fragment, v) for v in
                                                       (whole.values() if isinstance(whole, dict) else whole))
    if isinstance(fragment, list):
        return isinstance(whole, list) and all(any(_part_of(f, w) for w in whole) for f in fragment)
    return fragment == whole


@pytest.mark.parametrize("block", [pytest.param(b, id=b.where) for b in blocks("yaml")])
def test_yaml_example_is_valid(block, tmp_path):
    """Each YAML block is a model, a study or a verify table that modelgen accepts, or a part of a shipped file."""
    from modelgen.model.loading import load_model
    from modelgen.study.studyfile import load_study

    data = yaml.safe_load(block.text)
    if "model" in data and any(k in data for k in ("states", "navigation", "base")):
        path = tmp_path / f"{data['model']}.yaml"
        path.write_text(block.text, encoding="utf-8")
        assert load_model(path).name == data["model"]
    elif "study" in data:
        path = tmp_path / "study.yaml"
        path.write_text(block.text, encoding="utf-8")
        assert load_study(path).case_count == 1000
        assert _part_of(data, _shipped_yaml()), f"{block.where}: not the shipped study it says it is"
    elif "entries" in data:
        shipped = yaml.safe_load((REPO / "tests" / "checks" / "data" / "enu_doppler18_user_table.yaml").read_text())
        assert data == shipped, f"{block.where}: the page says it is tests/checks/data/enu_doppler18_user_table.yaml"
    elif "check" in data:
        pass  # flown by test_the_check_scenario_example_passes_the_compiled_check
    elif set(data) <= {"imu", "gnss"}:  # the log sections of a replay configuration
        from modelgen.navigator.logs import source_from_config

        for section, raw in data.items():
            (tmp_path / raw["file"]).write_bytes(b"")  # the reader is not run: the keys are checked
            assert source_from_config(section, raw, lambda key: block.where, tmp_path).section == section
    else:
        assert _part_of(data, _shipped_yaml()), f"{block.where}: a fragment that is in no shipped file"


@pytest.mark.compile
@pytest.mark.parametrize("model", ["schuler_loop", "vector_ins"])  # ins_gnss15_example: tests/model/test_navigation_model.py
def test_model_examples_with_a_check_scenario_pass_the_compiled_check(model, tmp_path):
    from modelgen.cli import main

    text = yaml_block("model-language.md", f"model: {model}")
    if model == "schuler_loop":  # the page's check: section is written for it
        text += yaml_block("model-language.md", "check:")
    path = tmp_path / f"{model}.yaml"
    path.write_text(text, encoding="utf-8")
    result = CliRunner().invoke(main, ["generate", str(path), "--out", str(tmp_path / "gen"), "--check"])
    assert result.exit_code == 0, result.output
    assert "check c" in result.output and "FAILED" not in result.output
    if model == "schuler_loop":
        assert "the model's check scenario (200 steps of 1 s)" in result.output or "200 steps" in result.output


@pytest.mark.compile
def test_the_c_usage_example_compiles_against_the_generated_header(tmp_path):
    """The page's C calls, given the variables it names, compile with the strict flags against generated/."""
    (block,) = blocks("c", [DOCS / "generated-code.md"])
    body = re.sub(r"\{ /\*[^}]*\*/ \}", "{ return 1; }", block.text)
    source = tmp_path / "usage.c"
    source.write_text(
        '#include "ned_doppler18.h"\n'
        "int usage(void);\n"
        "int usage(void) {\n"
        "    static ned_doppler18_params params; static ned_doppler18_matrices matrices;\n"
        "    static ned_doppler18_transition transition; static ned_doppler18_filter filter;\n"
        "    static ned_doppler18_workspace work; static double P0[18 * 18]; static double z[2];\n"
        + body + "    return 0;\n}\n", encoding="utf-8")
    run = subprocess.run(["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-c", str(source),
                          "-I", str(REPO / "generated" / "ned_doppler18"), "-o", str(tmp_path / "usage.o")],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr


@pytest.mark.compile
def test_the_cpp_usage_example_compiles_against_the_generated_class(tmp_path):
    """The page's C++ example compiles with g++ -std=c++17 and the strict flags against generated/'s class."""
    compiler = shutil.which("g++")
    if compiler is None:
        pytest.skip("g++ is not installed")
    (block,) = blocks("cpp", [DOCS / "generated-code.md"])
    source = tmp_path / "usage.cpp"
    source.write_text(block.text, encoding="utf-8")
    run = subprocess.run([compiler, "-std=c++17", "-Wall", "-Wextra", "-Werror", "-pedantic", "-c", str(source),
                          "-I", str(REPO / "generated" / "ned_doppler18"), "-o", str(tmp_path / "usage.o")],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
