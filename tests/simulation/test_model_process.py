"""`modelgen simulate`'s filter model derived in a forked process: the same flight, no sympy in the flying process."""

import re
import subprocess
import sys
import threading

import numpy as np
import pytest

from modelgen.errors import ModelError
from modelgen.simulation.flight_report import simulation_report
from modelgen.simulation.model_process import ModelProcess, PreparedModel, prepare_model
from modelgen.simulation.scenario import load_profile

pytestmark = pytest.mark.flight


def _fly(scenario, model, folder, runs):
    return simulation_report(scenario, model, folder, runs=runs, seed=0, workers=1, echo=lambda line: None, implementation="c",
                             history_csv=True)


def test_a_prepared_model_flies_the_histories_and_monte_carlo_of_the_derived_model(paper_derived, tmp_path):
    scenario = load_profile("profile_000").with_changes(hours=1 / 60, imu_rate=30.0)
    prepared = prepare_model(scenario, "c", runs=2)
    assert isinstance(prepared, PreparedModel) and prepared.model.state_names == tuple(paper_derived.model.state_names)
    here = _fly(scenario, paper_derived, tmp_path / "derived", runs=2)
    apart = _fly(scenario, prepared, tmp_path / "prepared", runs=2)
    for mode in ("open_loop", "closed_loop", "accumulated"):
        assert (tmp_path / "derived" / f"history_{mode}.csv").read_bytes() == \
            (tmp_path / "prepared" / f"history_{mode}.csv").read_bytes()
    for name in ("trajectory.png", "correction_modes.png", "filter_errors.png", "monte_carlo.png", "nees.png"):
        assert (tmp_path / "derived" / name).read_bytes() == (tmp_path / "prepared" / name).read_bytes(), name

    def without_timings(path):  # the summary but its section of timings and the seconds a step took
        text = path.read_text(encoding="utf-8")
        start = text.index("## Timings")
        return re.sub(r"\b\d+\.\d+ s\b", "(seconds)", text[:start] + text[text.index("\n## ", start):])

    assert without_timings(here.summary) == without_timings(apart.summary)


def test_the_model_process_answers_what_prepare_model_makes_here_and_raises_its_errors(tmp_path):
    scenario = load_profile("profile_000").with_changes(hours=1 / 60, imu_rate=30.0)
    if threading.active_count() > 1:
        pytest.skip("a thread runs in this test process: it forks no model process")
    process = ModelProcess.start(scenario, "c", 0)
    assert process._pid is not None  # forked
    apart, here = process.result(), prepare_model(scenario, "c", 0)
    assert apart.files == here.files and apart.units == here.units and apart.symbolic == here.symbolic
    assert apart.layout.conventions == here.layout.conventions
    assert all(np.array_equal(a, b) for a, b in zip(apart.outline.structures, here.outline.structures))
    broken = scenario.with_changes(model=str(tmp_path / "missing.yaml"))
    with pytest.raises(ModelError, match="missing.yaml"):
        ModelProcess.start(broken, "c", 0).result()


def test_modelgen_simulate_flies_without_importing_sympy(tmp_path):
    probe = (
        "import sys, modelgen.simulation.flight_report as report\n"
        "seen = []\n"
        "real = report.fly_modes\n"
        "def fly(*args, **kwargs):\n"
        "    seen.append(sorted(m for m in ('sympy', 'pint') if m in sys.modules))\n"
        "    return real(*args, **kwargs)\n"
        "report.fly_modes = fly\n"
        "from modelgen.cli import main\n"
        f"sys.argv = ['modelgen', 'simulate', '--hours', '0.01', '--imu-rate', '30', '--runs', '0', '--out', {str(tmp_path)!r}]\n"
        "try:\n"
        "    main()\n"
        "except SystemExit as end:\n"
        "    assert not end.code, end.code\n"
        "print('imported at the flight:', seen)\n"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "imported at the flight: [[]]" in done.stdout, done.stdout
