"""summary.md of ``modelgen simulate``: the scenario, the correction modes, the Monte Carlo runs, timings, figures."""

from __future__ import annotations

import math

import numpy as np

from modelgen.fileio.datafiles import display_path
from modelgen.simulation.flight_errors import ARCSEC
from modelgen.simulation.flight_figures import nees_verdict, runs_text


IMPLEMENTATION_TEXT = {
    "c": "the generated C (modelgen generate, default options), compiled for this run and driven, with the "
         "strapdown and the glue, by one compiled loop (modelgen/simulation/native_loop.py)",
    "python": "the generated Python module (modelgen generate, default options)",
    "reference": "the dense numpy reference filter (modelgen/derivation/reference.py)",
}


def summary_markdown(profile, model_name, implementation, conventions, trajectory, results, errors, mc, timings, figures,
                     units: dict[str, str] | None = None) -> str:
    lines = [
        f"# Simulation: {profile.title or profile.name}",
        "",
        f"Scenario `{profile.name}` ({display_path(profile.source_file) if profile.source_file else 'built in code'}), {profile.path.duration / 3600:.2f} h, "
        f"IMU {profile.imu_rate:g} Hz with {profile.coning}-sample coning/sculling, filter model `{model_name}`, "
        f"aiding {profile.filter.aiding} every {profile.aiding_period:g} s, "
        f"filter cycle {profile.filter.period:g} s.",
        "",
        ("Sign conventions identified from the model's F and H (+1: as the simulation defines them; "
         "see modelgen/simulation/error_layout.py): " + ", ".join(f"{k} {v:+.0f}" for k, v in conventions.items()) + "."
         if conventions else
         "Error states mapped explicitly (psi-angle attitude, ENU position in metres, receiver clock ranges; "
         "see modelgen/simulation/pseudorange.py)."),
        "",
        "## Correction modes (one run, identical sensor data)",
        "",
        f"Filter: {IMPLEMENTATION_TEXT[implementation]}.",
        "",
        "| output | final horizontal position error [m] | rms horizontal velocity error, last hour [m/s] | "
        "final heading error [arcsec] | updates | gate rejections | outage skips | refused |",
        "|---|---|---|---|---|---|---|---|",
    ]
    last_hour = errors["closed_loop"].times >= trajectory.truth[-1, 0] - 3600
    for label, e in errors.items():
        r = results.get(label)
        counts = f"{r.updates} | {len(r.rejected)} | {r.skipped} | {len(r.refused)}" if r else "- | - | - | -"
        lines.append(
            f"| {label} | {np.hypot(*e.position[-1]):.1f} | {np.sqrt(np.mean(np.sum(e.velocity[last_hour] ** 2, axis=1))):.3f} | "
            f"{e.attitude[-1, 2] / ARCSEC:.1f} | {counts} |"
        )
    cl, ac = errors["closed_loop"], errors["accumulated"]
    lines += [
        "",
        "The accumulated-correction paper's theorem says accumulated correction equals closed-loop feedback in the linear case "
        "(tests/simulation/test_integration.py checks it to 1e-9).  On this nonlinear flight the largest "
        f"difference between the two corrected outputs is {np.max(np.hypot(*(cl.position - ac.position).T)):.3g} m in position "
        f"and {np.max(np.abs(cl.attitude - ac.attitude)) / ARCSEC:.3g} arcsec in attitude.",
        "",
    ]
    free_ins = np.hypot(*errors["free INS"].position[-1])
    for mode, result in results.items():
        offered = result.updates + len(result.rejected)
        if offered and len(result.rejected) > 0.01 * offered:
            why = (f"In this mode the INS runs uncorrected and its error reaches {free_ins:.3g} m; at that size the "
                   "terms the first-order error model neglects (they grow with the square of the error) can exceed "
                   "the filter's sigma.  Closed-loop feedback keeps the errors small enough for the model to hold."
                   if mode != "closed_loop" else
                   "With feedback the errors stay small, so this points at the filter's tuning or model.")
            lines += [f"**{mode}: the gate rejected {len(result.rejected)} of {offered} measurements "
                      f"({100 * len(result.rejected) / offered:.0f} %).**  {why}", ""]
    if mc is not None:
        test = mc.nees_test(0.95, start_time=mc.times[1] if len(mc.times) > 1 else 0.0)
        rms, sigma = mc.ensemble_rms(), mc.mean_sigma()
        lines += [
            f"## Monte Carlo ({runs_text(mc.runs)}, {mc.mode}, {mc.seconds:.1f} s)",
            "",
            f"Filter: {IMPLEMENTATION_TEXT[implementation]}, built once per worker.",
            "",
            f"{nees_verdict(test)}; the band is [{test.lower:.2f}, {test.upper:.2f}] (n = {test.dimension}, "
            f"{len(test.times)} stored times)"
            + (", and one run is a weak test of consistency" if mc.runs == 1 else "")
            + f".  Gate rejections over {'the run' if mc.runs == 1 else 'all runs'}: {int(mc.rejected.sum())}.",
            "",
            ("| state | |error| of the run at end | filter sigma at end | ratio |" if mc.runs == 1 else
             "| state | error rms at end | filter sigma at end | ratio |"),
            "|---|---|---|---|",
        ]
        for i, name in enumerate(mc.state_names):
            ratio = rms[-1, i] / sigma[-1, i] if sigma[-1, i] > 0 else math.nan
            lines.append(f"| {name} | {rms[-1, i]:.4g} | {sigma[-1, i]:.4g} | {ratio:.2f} |")
        lines.append("")
    lines += ["## Timings", "", "| step | seconds |", "|---|---|"]
    lines += [f"| {k} | {v:.2f} |" for k, v in timings.items()]
    captions = figure_captions(profile, trajectory, results, mc, units)
    lines += ["", "## Figures", ""]
    for path in figures:
        lines += [f"![{path.stem}]({path.name})", "", captions.get(path.name, path.stem), ""]
    return "\n".join(lines)


def figure_captions(profile, trajectory, results, mc, units: dict[str, str]) -> dict[str, str]:
    """One line per figure of the flight (file name -> caption), saying what is drawn, in which units."""
    mode = profile.filter.mode
    shown = sorted(set((units or {}).values()) - {"?"})
    captions = {
        "trajectory.png": f"The flight profile {profile.name}: ground track, height (up to "
                          f"{float(np.max(trajectory.truth[:, 3])) / 1000:.2f} km), ground speed and climb rate, and "
                          "attitude (roll, pitch, yaw) of the simulated truth.",
        "correction_modes.png": "Horizontal position, horizontal velocity and heading errors of the corrected outputs "
                                "in each correction mode and of the free INS (one run, the same sensor data; log scale).",
        "filter_errors.png": f"Estimation error of each state in the {mode} run against the filter's +-3 sigma, one "
                             f"run, each panel in its engineering unit ({', '.join(shown)}).",
    }
    if mc is not None:
        test = mc.nees_test(0.95, start_time=mc.times[1] if len(mc.times) > 1 else 0.0)
        captions["monte_carlo.png"] = (
            f"The one Monte Carlo run ({mc.mode}): its absolute estimation error per state against the filter's sigma "
            "(one run: no ensemble statistic)." if mc.runs == 1 else
            f"Monte Carlo, {runs_text(mc.runs)} ({mc.mode}): the error rms per state against the filter's mean sigma.")
        captions["nees.png"] = nees_verdict(test)[0].upper() + nees_verdict(test)[1:] + "."
    return captions


def targets(mc) -> list[dict]:
    """The flight's stated target: the NEES criterion of the Monte Carlo runs (none without runs)."""
    if mc is None:
        return []
    test = mc.nees_test(0.95, start_time=mc.times[1] if len(mc.times) > 1 else 0.0)
    what = "NEES of the one run" if mc.runs == 1 else f"mean NEES over {runs_text(mc.runs)}"
    return [{"quantity": f"{what} inside its {100 * test.confidence:.0f} % chi-square band",
             "reached": f"{100 * test.fraction_inside:.0f} % of the times",
             "target": f">= {100 * (test.confidence - 0.1):.0f} %", "met": test.passed()}]
