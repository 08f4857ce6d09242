"""The command line: help for every command, clear errors, nothing half-written."""

import pytest
from click.testing import CliRunner

from modelgen.cli import main


@pytest.fixture
def runner():
    return CliRunner()


def test_every_command_has_help(runner):
    result = runner.invoke(main, ["--help"])
    assert result.exit_code == 0
    commands = [line.split()[0] for line in result.output.split("Commands:")[1].strip().splitlines()]
    assert {"derive", "generate"} <= set(commands)
    for command in commands:
        sub = runner.invoke(main, [command, "--help"])
        assert sub.exit_code == 0, command
        assert len(sub.output.splitlines()) > 3


def test_derive_prints_the_papers_entries(runner):
    result = runner.invoke(main, ["derive"])
    assert result.exit_code == 0
    assert "model ned_doppler18: 18 states, 6 noises, 2 measurements" in result.output
    assert "F(6,4) [latitude_error, velocity_error_north] = 1/R" in result.output


BAD_MODELS = {
    "unknown symbol": ("dynamics:\n  a: k*a + q\n", "unknown symbol(s) q"),
    "duplicate state": ("states:\n  - {name: a}\n  - {name: a}\ndynamics:\n  a: '0'\n", "declared twice"),
    "invalid identifier": ("states:\n  - {name: 2a}\ndynamics:\n  2a: '0'\n", "not a valid C identifier"),
    "C keyword": ("states:\n  - {name: double}\ndynamics:\n  double: '0'\n", "keyword"),
}


@pytest.mark.parametrize("case", sorted(BAD_MODELS))
def test_bad_model_file_is_refused_and_nothing_is_written(runner, tmp_path, case):
    body, message = BAD_MODELS[case]
    header = "model: toy\nparameters:\n  - {name: k}\n"
    if "states:" not in body:
        header += "states:\n  - {name: a}\n"
    path = tmp_path / "toy.yaml"
    path.write_text(header + body)
    out = tmp_path / "generated"
    result = runner.invoke(main, ["generate", str(path), "--out", str(out)])
    assert result.exit_code == 2
    assert message in result.output
    assert str(path) in result.output
    assert not out.exists()


def test_generate_writes_python_and_c(runner, tmp_path):
    result = runner.invoke(main, ["generate", "ned_doppler18", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    written = {p.name for p in (tmp_path / "ned_doppler18").iterdir()}
    assert {"ned_doppler18.c", "ned_doppler18.h", "ned_doppler18.py"} <= written


def test_run_does_the_main_job_end_to_end(runner, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(main, ["run", "--no-figures", "--no-simulate"])
    assert result.exit_code == 0, result.output
    assert "modelgen run: ok" in result.output
    report = (tmp_path / "report" / "README.md").read_text()
    assert "59 match" in report and "0 unexplained" in report
    assert "| ned_doppler18 | 18 |" in report and "FAILED" not in report
    assert (tmp_path / "report" / "verification.json").is_file()
    assert (tmp_path / "report" / "covariance" / "table2.csv").is_file()
    assert (tmp_path / "generated" / "ned_doppler18" / "ned_doppler18.c").is_file()


def test_simulate_flies_a_profile_with_the_generated_c_filter_and_writes_summary_and_figures(runner, tmp_path):
    out = tmp_path / "sim"
    result = runner.invoke(main, ["simulate", "--hours", "0.1", "--imu-rate", "20", "--runs", "2", "--filter", "c",
                                  "--out", str(out)])
    assert result.exit_code == 0, result.output
    summary = (out / "summary.md").read_text()
    assert "Filter: the generated C" in summary and "| closed_loop |" in summary and "NEES" in summary
    assert {"trajectory.png", "correction_modes.png", "filter_errors.png", "monte_carlo.png", "nees.png"} <= {
        p.name for p in out.iterdir()}
    assert not [p for p in out.rglob("*.so")]  # the filter was built in a temporary folder


def test_simulate_refuses_an_unknown_filter_implementation(runner, tmp_path):
    result = runner.invoke(main, ["simulate", "--filter", "fortran", "--out", str(tmp_path)])
    assert result.exit_code != 0 and "fortran" in result.output
