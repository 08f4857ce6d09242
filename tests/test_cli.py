"""The command line: help for every command, clear errors, nothing half-written."""

import json

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


@pytest.mark.flight
@pytest.mark.compile
def test_run_does_the_main_job_end_to_end(runner, tmp_path, monkeypatch, derived_builtin, mechanization_models):
    from modelgen import jobs
    from modelgen.checks import mechanizations
    from modelgen.model.loading import builtin_models

    # the job derives each built-in model (jobs.load_and_derive: derive(load_model(name))) and the mechanization
    # checks' three models as the session's fixtures do (tests/conftest.py): the same objects, which this worker's
    # later tests then take instead of loading the models again
    load_and_derive = jobs.load_and_derive
    monkeypatch.setattr(jobs, "load_and_derive",
                        lambda model: derived_builtin(model) if str(model) in builtin_models() else load_and_derive(model))
    monkeypatch.setattr(mechanizations, "derive_mechanization_models", lambda: mechanization_models)
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(main, ["run", "--no-figures", "--no-simulate"])
    assert result.exit_code == 0, result.output
    report = (tmp_path / "report" / "README.md").read_text()
    missed = [line for line in report.splitlines() if line.endswith("| **missed** |")]
    # ok only when every target the report states is met; a missed one is named on the last line
    assert ("modelgen run: ok, every target met" in result.output) == (not missed)
    assert ("modelgen run: checks passed, " in result.output) == bool(missed)
    assert "## Targets" in report and "| Recorded car drive | outage ends inside" in report
    assert "59 match" in report and "0 unexplained" in report
    assert "| ned_doppler18 | 18 |" in report and "FAILED" not in report
    assert (tmp_path / "report" / "verification.json").is_file()
    assert (tmp_path / "report" / "covariance" / "table2.csv").is_file()
    assert (tmp_path / "generated" / "ned_doppler18" / "ned_doppler18.c").is_file()
    assert "## Recorded car drive" in report and "end-of-outage horizontal error RMS" in report
    assert (tmp_path / "report" / "replay" / "summary.json").is_file()
    assert "## Hand-written models against their twins" in report and "Unexplained: **0**" in report
    assert "## The paper from first principles" in report and "F(4,5) (dV_n, dV_e), eq. (1): physics" in report
    assert (tmp_path / "report" / "crosscheck.json").is_file() and (tmp_path / "report" / "paper_equations.json").is_file()
    # the mechanizations' cross-checks (modelgen.checks.mechanizations): their section says every check passed
    assert "## Mechanizations cross-checked" in report and "Every check passed: **yes**" in report
    assert "| Mechanizations cross-checked | mechanization cross-checks outside their bound (incl. the polar flight) | 0 | 0 | met |" in report
    assert json.loads((tmp_path / "report" / "mechanizations.json").read_text())["passed"]


@pytest.mark.flight
@pytest.mark.compile
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


def test_the_scheduler_connect_timeout_is_ten_seconds_unless_told(monkeypatch):
    """--connect-timeout of simulate and trade defaults to modelgen.cluster.CONNECT_TIMEOUT_S, 10 s, and so does
    dask_client; the corpus's unreachable-scheduler cases (tests/corpus/trade_studies.yaml) set 1 s and see it named."""
    from modelgen import cluster
    from modelgen.cli import simulate, trade
    from modelgen.errors import ModelError

    assert cluster.CONNECT_TIMEOUT_S == 10.0
    for command in (simulate, trade):  # None: dask_client's default (the CLI does not import modelgen.cluster)
        (option,) = [p for p in command.params if p.name == "connect_timeout"]
        assert option.default is None and "--connect-timeout" in option.opts
        assert f"default: {cluster.CONNECT_TIMEOUT_S:g} s" in option.help
    waited = []

    def connect_within(connect, scheduler, timeout_s):
        waited.append(timeout_s)
        raise ModelError("not connecting")

    monkeypatch.setattr(cluster, "_connect_within", connect_within)
    for told in (None, 2.5):
        with pytest.raises(ModelError, match="not connecting"), cluster.dask_client("tcp://127.0.0.1:9", timeout_s=told):
            pass
    assert waited == [10.0, 2.5]


def test_simulate_refuses_an_unknown_filter_implementation(runner, tmp_path):
    result = runner.invoke(main, ["simulate", "--filter", "fortran", "--out", str(tmp_path)])
    assert result.exit_code != 0 and "fortran" in result.output


# -- output is never lost (issue 10, item 6) ----------------------------------------------------

TOY = """\
model: toy_loop
parameters:
  - {name: rate, symbol: k, value: 0.5}
  - {name: sigma, symbol: s, value: 0.1}
states:
  - {name: x_state, symbol: x}
noises:
  - {name: w_noise, symbol: w, psd: "s**2"}
dynamics:
  x: -k*x + w
measurements:
  - {name: z_meas, symbol: z, expression: x, variance: "s**2"}
"""


def _toy(tmp_path, rate="0.5"):
    path = tmp_path / "toy.yaml"
    path.write_text(TOY.replace("value: 0.5", f"value: {rate}"))
    return path


def _snapshot(folder):
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}


def _hidden(root):
    return sorted(p.name for p in root.iterdir() if p.name.startswith("."))


@pytest.mark.compile
def test_a_failing_check_exits_1_and_keeps_the_previous_output(runner, tmp_path, monkeypatch):
    import dataclasses

    from modelgen import jobs

    out = tmp_path / "out"
    assert runner.invoke(main, ["generate", str(_toy(tmp_path)), "--out", str(out), "--check"]).exit_code == 0
    before = _snapshot(out / "toy_loop")
    real_check = jobs.check

    def strict_check(derived, folder, scenario=None, options=None):  # the check really runs, against a zero tolerance
        assert folder != out / "toy_loop"  # checked in the staging folder, not in place
        return [dataclasses.replace(r, tolerance=0.0) for r in real_check(derived, folder, scenario, options)]

    monkeypatch.setattr(jobs, "check", strict_check)
    result = runner.invoke(main, ["generate", str(_toy(tmp_path, "0.25")), "--out", str(out), "--check"])
    assert result.exit_code == 1, result.output
    assert "-> FAILED" in result.output and "was left as it was" in result.output
    assert _snapshot(out / "toy_loop") == before
    assert _hidden(out) == []


def test_a_check_that_raises_keeps_the_previous_output(runner, tmp_path, monkeypatch):
    from modelgen import jobs
    from modelgen.errors import ModelError

    out = tmp_path / "out"
    assert runner.invoke(main, ["generate", str(_toy(tmp_path)), "--out", str(out)]).exit_code == 0
    before = _snapshot(out / "toy_loop")

    def broken_check(*args, **kwargs):
        raise ModelError("generated C for 'toy_loop' refused the step T = 0")

    monkeypatch.setattr(jobs, "check", broken_check)
    result = runner.invoke(main, ["generate", str(_toy(tmp_path, "0.25")), "--out", str(out), "--check"])
    assert result.exit_code == 2
    assert "modelgen: error: generated C for 'toy_loop' refused the step" in result.output
    assert _snapshot(out / "toy_loop") == before and _hidden(out) == []


def test_a_full_disk_gives_one_line_exit_2_and_nothing_half_written(runner, tmp_path, monkeypatch):
    import errno

    from modelgen.fileio import output

    out = tmp_path / "out"
    assert runner.invoke(main, ["generate", str(_toy(tmp_path)), "--out", str(out)]).exit_code == 0
    before = _snapshot(out / "toy_loop")
    written = []

    def full(path, text):
        written.append(path)
        if len(written) == 3:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        path.write_text(text)

    monkeypatch.setattr(output, "_write_text", full)
    result = runner.invoke(main, ["generate", str(_toy(tmp_path, "0.25")), "--out", str(out)])
    assert result.exit_code == 2
    # the file the user asked for, not its copy in the staging folder (issue 28)
    assert f"modelgen: error: {out / 'toy_loop' / written[-1].name}: No space left on device" in result.output
    assert "Traceback" not in result.output
    assert _snapshot(out / "toy_loop") == before and _hidden(out) == []


# -- one error boundary (issue 10, item 9) -------------------------------------------------------


def test_an_internal_error_exits_3_without_traceback_and_debug_shows_it(runner, tmp_path, monkeypatch):
    from modelgen import jobs

    def bug(model):
        raise RuntimeError("a bug")

    monkeypatch.setattr(jobs, "derive", bug)
    result = runner.invoke(main, ["derive"])
    assert result.exit_code == 3
    assert "modelgen: error: internal error: RuntimeError: a bug" in result.output and "--debug" in result.output
    debug = runner.invoke(main, ["--debug", "derive"])
    assert isinstance(debug.exception, RuntimeError)


def test_debug_lets_a_bad_input_error_through_with_its_traceback(runner, tmp_path):
    from modelgen.errors import ModelError

    result = runner.invoke(main, ["--debug", "derive", str(tmp_path / "nope.yaml")])
    assert isinstance(result.exception, ModelError) and "nope.yaml" in str(result.exception)


def test_interrupt_exits_130_and_says_so(runner, monkeypatch):
    from modelgen import jobs

    def interrupted(name):
        raise KeyboardInterrupt

    monkeypatch.setattr(jobs, "load_model", interrupted)
    result = runner.invoke(main, ["derive"])
    assert result.exit_code == 130
    assert "modelgen: interrupted" in result.output


def test_python_warnings_are_printed_as_modelgen_warnings(runner, monkeypatch):
    import warnings

    from modelgen import jobs

    real = jobs.derive

    def noisy(model):
        warnings.warn("model has 900 states: the generated C will be about 40 MB")
        return real(model)

    monkeypatch.setattr(jobs, "derive", noisy)
    result = runner.invoke(main, ["derive"])
    assert result.exit_code == 0
    assert "modelgen: warning: model has 900 states: the generated C will be about 40 MB" in result.output


def test_printer_errors_become_bad_input_errors():
    import sympy as sp
    from sympy.printing.c import C99CodePrinter

    from modelgen.cli import EXIT_BAD_INPUT, error_message

    try:
        C99CodePrinter({"strict": True}).doprint(sp.Integral(sp.Symbol("x"), sp.Symbol("x")))
    except Exception as exc:  # noqa: BLE001 - whatever sympy raises, it comes from its printer
        message, code = error_message(exc)
    assert code == EXIT_BAD_INPUT and message.startswith("an expression cannot be printed as code")
    assert error_message(TypeError("not from a printer")) is None  # a bug elsewhere stays an internal error


@pytest.mark.parametrize("module", ["modelgen", "modelgen.cli"])
def test_python_dash_m_runs_the_command_line(module):
    import subprocess
    import sys

    result = subprocess.run([sys.executable, "-m", module, "--help"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and "Usage: modelgen" in result.stdout and "--debug" in result.stdout


def test_generate_into_a_path_below_a_file_is_a_one_line_error(runner, tmp_path):
    (tmp_path / "file").write_text("x")
    result = runner.invoke(main, ["generate", str(_toy(tmp_path)), "--out", str(tmp_path / "file" / "sub")])
    assert result.exit_code == 2
    assert result.output.startswith("modelgen: error: ") and "Not a directory" in result.output



def test_concurrent_generates_into_one_folder_all_succeed_and_leave_it_whole(tmp_path):
    import subprocess
    import sys

    model, out = _toy(tmp_path), tmp_path / "out"
    command = [sys.executable, "-m", "modelgen", "generate", str(model), "--out", str(out)]
    for _ in range(3):
        procs = [subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) for _ in range(8)]
        results = [(p.wait(180), p.stdout.read()) for p in procs]
        assert [code for code, _ in results] == [0] * 8, results
        assert not any("Traceback" in text for _, text in results)
        assert sorted(p.name for p in (out / "toy_loop").iterdir()) == sorted(
            [
                    ".modelgen-manifest.json", "CMakeLists.txt", "Makefile", "README.md", "toy_loop.c", "toy_loop.h",
                    "toy_loop.hpp", "toy_loop.py", *(f"modelgen_{part}.h" for part in ("factor", "ieee", "lane_pair", "scalar", "taylor")),
                ]
        )
        assert _hidden(out) == []


@pytest.mark.compile
def test_sigint_during_generate_exits_130_and_leaves_nothing_half_written(tmp_path):
    """SIGINT while the new output is being written or checked: exit 130, the old output whole, no staging left.

    Each interrupt is sent at a known point of the run, not after a fixed sleep (which, on a loaded machine,
    lands while the interpreter is still starting): once the run's staging folder beside the output exists
    (modelgen.fileio.output: the files are being written, then compiled and checked there), and then later
    by 0.25 to 2 s, while the check runs or after the new output was committed.
    """
    import signal
    import subprocess
    import sys
    import time

    from modelgen.fileio.output import STAGING_INFIX

    model, out = _toy(tmp_path), tmp_path / "out"
    subprocess.run([sys.executable, "-m", "modelgen", "generate", str(model), "--out", str(out)], check=True,
                   capture_output=True, timeout=120)
    before = _snapshot(out / "toy_loop")
    (out / "toy_loop" / "main.c").write_text("int main(void) { return 0; }\n")
    codes = []
    for after_staging in (0.0, 0.25, 0.75, 2.0):
        proc = subprocess.Popen([sys.executable, "-m", "modelgen", "generate", str(_toy(tmp_path, "0.25")), "--out", str(out), "--check"],
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        deadline = time.monotonic() + 120
        while not any(STAGING_INFIX in p.name for p in out.iterdir()):  # the readiness signal: the run is writing
            assert proc.poll() is None, f"exited {proc.returncode} before staging its output: {proc.stdout.read()}"
            assert time.monotonic() < deadline, "no staging folder within 120 s"
            time.sleep(0.005)
        time.sleep(after_staging)
        proc.send_signal(signal.SIGINT)
        code, text = proc.wait(120), proc.stdout.read()
        # 130: interrupted, nothing written; 0 or death by SIGINT: the signal came after the output was complete
        assert code in (0, 130, -signal.SIGINT), text
        codes.append(code)
        assert "Traceback" not in text
        if code == 130:
            assert "modelgen: interrupted" in text
        after = _snapshot(out / "toy_loop")
        assert after["main.c"] == b"int main(void) { return 0; }\n"
        del after["main.c"]
        assert after.keys() == before.keys()  # the old or the new output, whole
        assert _hidden(out) == []
    # the interrupt sent as soon as the staging folder appeared came mid-way (the compile and check take seconds)
    assert codes[0] == 130, codes


def test_observability_without_scenario_uses_the_models_check_scenario(runner):
    """A model the paper's level flight does not cover is analysed at its own check scenario, not refused."""
    result = runner.invoke(main, ["observability", "ins_gnss21"])
    assert result.exit_code == 0, result.output
    assert "scenario: the model's check scenario (steps of 1 s)" in result.output
    assert "rank of the observability matrix: 19 of 21" in result.output  # level, unaccelerated: tilt ~ accel bias


@pytest.mark.parametrize("force", [[], ["--force"]])
def test_derive_out_onto_a_named_pipe_is_refused_and_the_pipe_kept(runner, tmp_path, force):
    """Issue 28: ``derive --out /dev/full --force`` (as root) replaced the device node with a regular file."""
    import os

    pipe = tmp_path / "pipe"
    os.mkfifo(pipe)
    result = runner.invoke(main, ["derive", "ned_doppler18", "--format", "json", "--out", str(pipe), *force])
    assert result.exit_code == 2
    assert result.output.strip() == (f"modelgen: error: {pipe}: is a named pipe, and modelgen replaces only regular "
                                     "files (even with --force): move it away or give another --out")
    assert pipe.is_fifo() and sorted(p.name for p in tmp_path.iterdir()) == ["pipe"]


def test_derive_out_onto_a_device_node_is_refused_and_the_node_kept(runner, tmp_path):
    """Issue 28's own case: ``derive --out /dev/full --force``, on a copy of the node (mknod needs root: else skipped)."""
    import os
    import stat

    device = tmp_path / "full"
    try:
        os.mknod(device, stat.S_IFCHR | 0o600, os.makedev(1, 7))  # /dev/full's major and minor numbers
    except (PermissionError, OSError) as exc:
        pytest.skip(f"cannot make a device node here: {exc}")
    result = runner.invoke(main, ["derive", "ned_doppler18", "--format", "json", "--out", str(device), "--force"])
    assert result.exit_code == 2
    assert result.output.strip() == (f"modelgen: error: {device}: is a device, and modelgen replaces only regular "
                                     "files (even with --force): move it away or give another --out")
    assert stat.S_ISCHR(os.lstat(device).st_mode) and sorted(p.name for p in tmp_path.iterdir()) == ["full"]


def test_an_interrupt_swallowed_by_a_c_callback_is_delivered_again_without_a_traceback(capfd):
    """Ctrl-C landing in a C callback into Python (llvmlite's object cache while numba compiles: seen once in CI as
    'Exception ignored ... Traceback' from test_sigint_during_generate_exits_130_and_leaves_nothing_half_written,
    and the interrupt lost) is raised again in the main thread as soon as the C code returns, and nothing is
    printed: the command then ends as for any other Ctrl-C (one line, exit 130)."""
    import ctypes
    import time

    from modelgen.cli import _interrupts_not_swallowed

    def callback() -> None:
        raise KeyboardInterrupt

    swallowing = ctypes.CFUNCTYPE(None)(callback)
    with pytest.raises(KeyboardInterrupt):
        with _interrupts_not_swallowed():
            swallowing()  # ctypes cannot propagate it: it goes to sys.unraisablehook
            time.sleep(5)  # the interrupt delivered again ends this wait at once
    assert "Traceback" not in capfd.readouterr().err
