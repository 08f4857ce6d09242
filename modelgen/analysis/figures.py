"""Analogues of the paper's Figs 2-7: error standard deviations over the 4-h run.

Fig 2: pure inertial attitude and heading errors; Fig 3: pure inertial
velocity and position errors; Figs 4-7: integrated systems (optimal and
suboptimal I-IV) attitude, heading, velocity and position (CEP) errors.
PNG via matplotlib's Agg backend, without date metadata.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from modelgen.analysis.systems import PURE_INERTIAL, SystemResult  # noqa: E402

_METADATA = {"Software": None}  # no version/date strings in the PNG


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110, metadata=_METADATA)
    plt.close(fig)
    return path


def _panel(ax, results: Mapping[str, SystemResult], times_h, key: str, title: str, unit: str) -> None:
    """One quantity of several systems against time."""
    styles = ("-", "--", "-.", ":", (0, (5, 1, 1, 1)))
    for i, r in enumerate(results.values()):
        ax.plot(times_h, r.errors[key], label=r.label, linestyle=styles[i % len(styles)], linewidth=2.0 if i == 0 else 1.4)
    ax.set(title=title, xlabel="time (h)", ylabel=unit)
    ax.grid(True, alpha=0.3)


def write_figures(results: Mapping[str, SystemResult], times_h, out_dir: str | Path) -> list[Path]:
    """Write the Fig 2-7 analogues into ``out_dir``; returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    integ = {k: r for k, r in results.items() if k != PURE_INERTIAL}
    e = results[PURE_INERTIAL].errors
    paths = []

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    axes[0].plot(times_h, e["attitude_error_north"], label="alpha (about north)")
    axes[0].plot(times_h, e["attitude_error_east"], label="beta (about east)")
    axes[0].set(title="Fig 2: pure inertial attitude errors", xlabel="time (h)", ylabel="arcsec (1 sigma)")
    axes[1].plot(times_h, e["heading_error"], label="gamma (about down)")
    axes[1].set(title="Fig 2: pure inertial heading error", xlabel="time (h)", ylabel="deg (1 sigma)")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend()
    paths.append(_save(fig, out / "fig2_pure_inertial_attitude.png"))

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    e = results[PURE_INERTIAL].errors
    axes[0].plot(times_h, e["velocity_error_north"], label="dV_n")
    axes[0].plot(times_h, e["velocity_error_east"], label="dV_e")
    axes[0].set(title="Fig 3: pure inertial velocity errors", xlabel="time (h)", ylabel="nmile/h (1 sigma)")
    axes[1].plot(times_h, e["position_error_north"], label="north (1 sigma)")
    axes[1].plot(times_h, e["position_error_east"], label="east (1 sigma)")
    axes[1].plot(times_h, e["position_cep"], label="CEP", linewidth=2)
    axes[1].set(title="Fig 3: pure inertial position error", xlabel="time (h)", ylabel="nmile")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend()
    paths.append(_save(fig, out / "fig3_pure_inertial_velocity_position.png"))

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    _panel(axes[0], integ, times_h, "attitude_error_north", "Fig 4: integrated, alpha", "arcsec (1 sigma)")
    _panel(axes[1], integ, times_h, "attitude_error_east", "Fig 4: integrated, beta", "arcsec (1 sigma)")
    axes[1].legend()
    paths.append(_save(fig, out / "fig4_integrated_attitude.png"))

    fig, ax = plt.subplots(figsize=(6, 4))
    _panel(ax, integ, times_h, "heading_error", "Fig 5: integrated, heading error gamma", "deg (1 sigma)")
    ax.legend()
    paths.append(_save(fig, out / "fig5_integrated_heading.png"))

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    _panel(axes[0], integ, times_h, "velocity_error_north", "Fig 6: integrated, dV_n", "nmile/h (1 sigma)")
    _panel(axes[1], integ, times_h, "velocity_error_east", "Fig 6: integrated, dV_e", "nmile/h (1 sigma)")
    axes[1].legend()
    paths.append(_save(fig, out / "fig6_integrated_velocity.png"))

    fig, ax = plt.subplots(figsize=(6, 4))
    _panel(ax, integ, times_h, "position_cep", "Fig 7: integrated, position error (CEP)", "nmile")
    ax.legend()
    paths.append(_save(fig, out / "fig7_integrated_position.png"))
    return paths
