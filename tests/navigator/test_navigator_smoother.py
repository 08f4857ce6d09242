"""The RTS smoother of a closed-loop error-state flight: exact on a linear system, better in outages on the drive."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from modelgen.navigator.smoother import ForwardRecord, backward_pass, smoothed_nominals
from tests.navigator.rts_reference import NumpyReference

DATA = Path(__file__).parent / "data"


def _constant_velocity(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """1-D constant velocity: state (position, velocity), white acceleration of PSD q."""
    Phi = np.array([[1.0, dt], [0.0, 1.0]])
    Q = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    return Phi, Q


def _fixes(steps: int, gap: range, seed: int = 7) -> tuple[list[list[float]], np.ndarray]:
    """Position fixes per step (none in the gap, two at some steps), and the true states."""
    rng = np.random.default_rng(seed)
    Phi, Q = _constant_velocity(0.1, 0.5)
    truth = [np.array([0.0, 2.0])]
    for _ in range(steps - 1):
        truth.append(Phi @ truth[-1] + rng.multivariate_normal(np.zeros(2), Q))
    fixes = []
    for k in range(steps):
        count = 0 if k in gap else (2 if k % 7 == 3 else 1)
        fixes.append([float(truth[k][0] + 0.3 * rng.standard_normal()) for _ in range(count)])
    return fixes, np.array(truth)


def _textbook_rts(fixes, x0, P0, Phi, Q, H, R):
    """Full-state Kalman filter then the textbook RTS smoother (the reference)."""
    xs_f, Ps_f, xs_p, Ps_p = [], [], [], []
    x, P = x0.copy(), P0.copy()
    for k, zs in enumerate(fixes):
        if k > 0:
            x, P = Phi @ x, Phi @ P @ Phi.T + Q
        xs_p.append(x.copy())
        Ps_p.append(P.copy())
        for z in zs:
            S = H @ P @ H.T + R
            K = P @ H.T / S
            x = x + (K * (z - H @ x)).ravel()
            P = (np.eye(2) - K @ H) @ P
        xs_f.append(x.copy())
        Ps_f.append(P.copy())
    xs, Ps = [xs_f[-1]], [Ps_f[-1]]
    for k in range(len(fixes) - 2, -1, -1):
        A = Ps_f[k] @ Phi.T @ np.linalg.inv(Ps_p[k + 1])
        xs.insert(0, xs_f[k] + A @ (xs[0] - xs_p[k + 1]))
        Ps.insert(0, Ps_f[k] + A @ (Ps[0] - Ps_p[k + 1]) @ A.T)
    return np.array(xs), np.array(Ps)


def _closed_loop_error_state(fixes, x0, P0, Phi, Q, H, R):
    """The same system flown as the navigator flies: nominal propagated, error state reset after each fix.

    Error e = nominal - truth; a fix z gives the error measurement nominal_position - z; the
    feedback subtracts the estimate.  Outputs are written after each step's first fix (and at
    steps without one), so some outputs precede a second correction at the same step.
    """
    def feedback(nav, sensors, dx):
        nav -= dx

    record = ForwardRecord()
    nominal, P = x0.copy(), P0.copy()
    record.start(P, feedback)
    output_steps = []
    for k, zs in enumerate(fixes):
        if k > 0:
            nominal = Phi @ nominal
            P = Phi @ P @ Phi.T + Q
            record.predicted(Phi, P)
        for i, z in enumerate(zs):
            S = H @ P @ H.T + R
            K = P @ H.T / S
            dx = (K * (H @ nominal - z)).ravel()  # x = 0 before the update: the estimate is the correction
            P = (np.eye(2) - K @ H) @ P
            record.corrected(dx, P)
            feedback(nominal, {}, dx)
            if i == 0:
                record.output(nominal, {}, lambda nav, sensors, cov: [*nav, cov[0, 0]])
                output_steps.append(k)
        if not zs:
            record.output(nominal, {}, lambda nav, sensors, cov: [*nav, cov[0, 0]])
            output_steps.append(k)
    return record, output_steps


def test_error_state_smoother_with_resets_matches_the_textbook_full_state_rts():
    """1-D constant velocity, position fixes, a 4-s gap, two fixes at some steps: states and covariances agree."""
    fixes, _ = _fixes(150, range(40, 80))
    Phi, Q = _constant_velocity(0.1, 0.5)
    H, R = np.array([[1.0, 0.0]]), np.array([[0.09]])
    x0, P0 = np.array([0.5, 1.0]), np.diag([4.0, 4.0])
    reference, reference_P = _textbook_rts(fixes, x0, P0, Phi, Q, H, R)
    record, output_steps = _closed_loop_error_state(fixes, x0, P0, Phi, Q, H, R)
    smoothed = smoothed_nominals(record, NumpyReference())
    states = np.array([nav for nav, _, _ in smoothed])
    covariances = np.array([P for _, _, P in smoothed])
    assert len(states) == len(fixes)
    np.testing.assert_allclose(states, reference[output_steps], rtol=0, atol=1e-9)
    np.testing.assert_allclose(covariances, reference_P[output_steps], rtol=0, atol=1e-9)
    # the smoother really moved the gap: the forward nominal there is far from the smoothed one
    forward = np.array([s.nav for s in record.outputs])
    assert np.abs(forward[40:80, 0] - states[40:80, 0]).max() > 0.1


def test_smoothed_error_is_zero_at_the_last_step_and_the_covariance_shrinks():
    fixes, _ = _fixes(60, range(20, 40))
    Phi, Q = _constant_velocity(0.1, 0.5)
    record, _ = _closed_loop_error_state(fixes, np.zeros(2), np.eye(2), Phi, Q, np.array([[1.0, 0.0]]),
                                         np.array([[0.09]]))
    steps = backward_pass(record, NumpyReference())
    assert np.all(steps.error[-1] == 0.0)
    in_gap = [np.trace(steps.covariance[k]) < np.trace(record.posteriors[k]) for k in range(20, 40)]
    assert all(in_gap)


def test_a_flight_without_its_record_is_refused():
    from modelgen.errors import ModelError
    from modelgen.navigator.navigator import Flight
    from modelgen.navigator.smoother import smooth_flight

    with pytest.raises(ModelError, match="without its forward record"):
        smooth_flight(Flight(np.zeros((1, 3)), [], 0.0, 0.0), NumpyReference())


@pytest.mark.flight
def test_on_the_drive_excerpt_the_smoothed_outage_error_is_below_the_forward_one():
    """The excerpt's 15-s outage: forward ends about 4 m off; the smoothed trajectory stays within 1 m."""
    from modelgen.navigator.logs import read_gnss
    from modelgen.navigator.metrics import errors_against_reference
    from modelgen.navigator.replay import run_replay

    result = run_replay(DATA / "excerpt.yaml", None, echo=lambda _: None, navigator="python", smooth=True)
    forward, smoothed = result.flight, result.smoothed
    reference = read_gnss(result.config.gnss_source)
    (start, end), = forward.outages
    e_forward = errors_against_reference(forward, reference)
    e_smoothed = errors_against_reference(smoothed, reference)
    inside = (e_forward.time >= start) & (e_forward.time < end)
    forward_max, smoothed_max = e_forward.horizontal[inside].max(), e_smoothed.horizontal[inside].max()
    assert forward_max > 1.0
    assert smoothed_max < 0.25 * forward_max
    assert smoothed_max < 1.0
    # the smoothed sigma is below the forward one in the outage (more data used), never above it anywhere
    assert np.all(e_smoothed.sigma_horizontal[inside] < e_forward.sigma_horizontal[inside])
    assert np.all(e_smoothed.sigma_horizontal <= e_forward.sigma_horizontal + 1e-9)


@pytest.mark.flight
def test_replay_smooth_flag_reports_smoothed_errors_beside_the_forward_ones(tmp_path):
    """`modelgen replay --smooth` on the excerpt (C navigator): summary, targets, smoothed trajectory files."""
    from click.testing import CliRunner

    from modelgen.cli import main

    out = tmp_path / "replay"
    result = CliRunner().invoke(main, ["replay", str(DATA / "excerpt.yaml"), "--out", str(out), "--smooth"])
    assert result.exit_code == 0, result.output
    assert "smoothed: horizontal RMS over every outage epoch" in result.output
    summary = json.loads((out / "summary.json").read_text())
    smoothed = summary["smoothed"]
    assert smoothed["steps"] > 500
    assert smoothed["smoothed"]["horizontal_error_outage_rms_m"] < smoothed["forward"]["horizontal_error_outage_rms_m"]
    (outage,) = smoothed["outages"]
    assert outage["smoothed_horizontal_error_max_m"] < outage["forward_horizontal_error_max_m"]
    # the forward beside it is the Python pass the smoother ran on: the C's end error within 1 mm
    assert abs(outage["forward_horizontal_error_end_m"] - summary["outages"][0]["horizontal_error_end_m"]) < 1e-3
    assert smoothed["outage_rms_met"] is None  # the excerpt states no smoothed target: nothing called met
    assert "smoothed.svg" in summary["figures"]
    forward_rows = (out / "trajectory.csv").read_text().splitlines()
    smoothed_rows = (out / "smoothed.csv").read_text().splitlines()
    assert smoothed_rows[0] == forward_rows[0] and len(smoothed_rows) == len(forward_rows)
    assert [r.split(",")[0] for r in smoothed_rows] == [r.split(",")[0] for r in forward_rows]
    assert "RTS-smoothed" in (out / "smoothed.pos").read_text().splitlines()[1]
    assert (out / "smoothed.svg").read_text().lstrip().startswith("<?xml")
    assert "## Smoothed (replay --smooth)" in (out / "summary.md").read_text()


def test_smoothed_targets_come_from_the_configuration(tmp_path):
    from modelgen.navigator.config import load_config

    text = (DATA / "excerpt.yaml").read_text()
    assert "target_smoothed_outage" not in text
    path = tmp_path / "excerpt.yaml"
    path.write_text(text.replace("imu:\n", "evaluation:\n  target_smoothed_outage_rms_m: 0.3\n"
                                           "  target_smoothed_outage_max_m: 0.7\nimu:\n", 1)
                    .replace("file: excerpt", f"file: {DATA}/excerpt"))
    config = load_config(path)
    assert (config.target_smoothed_outage_rms_m, config.target_smoothed_outage_max_m) == (0.3, 0.7)
    path.write_text(path.read_text().replace("target_smoothed_outage_rms_m: 0.3", "target_smoothed_outage_rms_m: -1"))
    from modelgen.errors import ModelError

    with pytest.raises(ModelError, match="target_smoothed_outage_rms_m"):
        load_config(path)
