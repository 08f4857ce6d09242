"""`modelgen replay`: fly a recorded drive with the navigator and write report/replay/."""

from __future__ import annotations

from pathlib import Path

import click

from modelgen.navigator.config import builtin_config_path


@click.command("replay")
@click.argument("config", required=False, type=click.Path(dir_okay=False, path_type=Path))
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="folder of the report (replaced as a whole) [default: the configuration's output.folder, "
                   "else report/replay]")
@click.option("--no-figures", is_flag=True, help="skip the SVG figures")
@click.option("--force", is_flag=True, help="replace an output folder modelgen did not write")
@click.option("--navigator", type=click.Choice(["c", "python", "both"]), default="c", show_default=True,
              help="the generated C navigator, the Python reference, or both (compared)")
@click.option("--embedded", is_flag=True,
              help="also build for Cortex-M4F (float filter; size, stack) and replay under qemu-arm against the double C")
@click.option("--smooth", is_flag=True,
              help="also run the RTS smoother over the forward pass (post-processing): smoothed errors beside the "
                   "forward ones, smoothed.pos/.csv/.svg")
def replay(config: Path | None, out: Path | None, no_figures: bool, force: bool, navigator: str, embedded: bool,
           smooth: bool) -> None:
    """Fly a GNSS/IMU log with the generated navigator (default: the built-in car drive).

    CONFIG is a navigator configuration (YAML); without it the built-in drive
    (modelgen/data/replay_drive_0708.yaml, 549 s, 11 simulated GNSS outages)
    is flown.  Writes the trajectory (.pos, .csv), summary.md, summary.json and
    figures into --out.

    Flying your own logs: every configuration key with its unit and default,
    the log formats (CSV IMU, RTKLIB .pos, PX4 ULog, ROS 2 bag), the outage
    and evaluation schedules and what each summary number means are in the
    README section "Flying your own logs" and docs/replay-configuration.md;
    the JSON schema is modelgen/data/replay_config.schema.json.
    """
    from modelgen.navigator.replay import run_replay

    path = config or builtin_config_path()
    result = run_replay(path, out if out is not None else report_folder(path), echo=lambda m: click.echo(m, err=True),
                        with_figures=not no_figures, force=force, navigator=navigator, embedded=embedded, smooth=smooth)
    s = result.summary
    click.echo(f"{s['outage_count']} outages: end-of-outage horizontal error RMS "
               f"{s['horizontal_error_end_rms_m']:.2f} m (median {s['horizontal_error_end_median_m']:.2f} m, "
               f"max {s['horizontal_error_end_max_m']:.2f} m), "
               f"mean NEES {s['consistency']['nees_mean']:.1f} (2 if consistent), "
               f"{100 * s['consistency']['inside_95_fraction']:.0f} % inside the 95 % region; "
               f"horizontal RMS outside outages {s['horizontal_rms_outside_outages_m']:.3f} m"
               if s["outage_count"] else
               f"no outages; horizontal RMS {s['horizontal_rms_outside_outages_m']:.3f} m")
    if len(s.get("schedules", [])) > 1:
        pooled = s["consistency_pooled"]
        click.echo(f"{len(s['schedules'])} outage schedules pooled ({pooled['count']} outage ends): mean NEES "
                   f"{pooled['nees_mean']:.1f}, {100 * pooled['inside_95_fraction']:.0f} % inside the 95 % region")
    if "c_python_max_difference_m" in s:
        click.echo(f"C and Python trajectories agree within {s['c_python_max_difference_m']:.3g} m")
    if "smoothed" in s and s["smoothed"]["smoothed"]["horizontal_error_outage_rms_m"] is not None:
        sm = s["smoothed"]
        verdicts = [f"{name} {'met' if met else 'missed'}" for name, met in
                    (("RMS target", sm["outage_rms_met"]), ("maximum target", sm["outage_max_met"])) if met is not None]
        click.echo(f"smoothed: horizontal RMS over every outage epoch {sm['smoothed']['horizontal_error_outage_rms_m']:.3f} m "
                   f"(forward {sm['forward']['horizontal_error_outage_rms_m']:.3f} m), largest outage maximum "
                   f"{sm['smoothed']['horizontal_error_outage_max_m']:.3f} m (forward "
                   f"{sm['forward']['horizontal_error_outage_max_m']:.3f} m)" + (f"; {', '.join(verdicts)}" if verdicts else ""))
    click.echo(f"navigator ({s['navigator']}) {result.timings['fly_s']:.2f} s, total {result.timings['total_s']:.2f} s; "
               f"report in {result.folder}")


DEFAULT_REPORT = Path("report/replay")


def report_folder(config_path: Path) -> Path:
    """The report folder when --out is not given: the configuration's output.folder, else report/replay."""
    from modelgen.navigator.config import load_config

    return load_config(config_path).output_folder or DEFAULT_REPORT
