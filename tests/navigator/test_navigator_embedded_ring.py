"""The qemu-arm / Cortex-M4F navigator is built with the alignment ring the configuration needs (-D<P>_NAV_REST_MAX).

A 20-s rest window over an excerpt made still before its rest epoch levels from 1150 IMU samples, more than the
default ring of 1024: the host C is built with a ring of 2048 (cnav.rest_capacity); the ARM build must be too, or
its navigator cannot align where the host's did (before the fix: the qemu driver exited 23).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tests.navigator.qemu_support import needs_qemu_arm

DATA = Path(__file__).parent / "data"



@needs_qemu_arm
@pytest.mark.embedded
@pytest.mark.compile
@pytest.mark.flight
def test_the_arm_build_has_the_configurations_rest_ring_and_flies_like_the_host_c():
    from modelgen.navigator.cnav import REST_MAX, cached_c_navigator, fly_c, log_arrays
    from modelgen.navigator.config import load_config
    from modelgen.navigator.embedded import embedded_replay
    from modelgen.navigator.errorstate import model_path
    from modelgen.navigator.logs import read_imu_csv, read_rtklib_pos
    from modelgen.navigator.navigator import prepare
    from modelgen.navigator.spec import navigator_spec

    config = load_config(DATA / "excerpt.yaml")
    inputs = prepare(config, read_imu_csv(config.imu_file, config.imu_columns, config.gap_factor),
                     read_rtklib_pos(config.gnss_file))
    # the excerpt's samples before its still span (7 s before the rest epoch) replaced by that span's, repeated
    first_still = inputs.first_epoch + 4.5
    span = np.nonzero((inputs.time >= first_still) & (inputs.time <= first_still + 6.9))[0]
    before = np.nonzero(inputs.time < first_still)[0]
    source = span[np.arange(len(before)) % len(span)]
    force, rate = inputs.force.copy(), inputs.rate.copy()
    force[before], rate[before] = inputs.force[source], inputs.rate[source]
    quiet = replace(inputs, force=force, rate=rate)
    long_window = replace(config, rest_window=20.0)
    spec = navigator_spec(model_path(config.model, config.path), with_python=False)
    arrays = log_arrays(long_window, quiet, spec)
    assert arrays.rest_max > REST_MAX
    navigator, _ = cached_c_navigator(spec, rest_max=arrays.rest_max)
    host, _ = fly_c(long_window, quiet, navigator)
    assert host.alignment["rest_samples"] > REST_MAX  # the window really needs the larger ring
    arm = embedded_replay(spec, arrays, host.outputs)
    assert arm.forbidden_symbols == []
    assert arm.max_position_difference_m <= 0.01  # measured 2.3e-5 m
