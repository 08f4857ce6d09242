"""Structural patterns predict exactly where the numbers can be nonzero."""

import numpy as np

from modelgen.codegen.structure import filter_structure, reachability
from modelgen.derivation.discretization import taylor_discretization, taylor_process_noise


def test_reachability_of_a_chain_is_its_upper_triangle():
    F = np.diag([True] * 3, k=1)  # 0 <- 1 <- 2 <- 3
    assert np.array_equal(reachability(F, 9), np.triu(np.ones((4, 4), bool)))
    assert not reachability(F, 1)[0, 2]  # two steps away needs order 2


def test_numeric_phi_and_qd_vanish_outside_the_structure(paper_derived, level_flight):
    s = filter_structure(paper_derived.structure("F"), paper_derived.structure("G"), paper_derived.structure("H"), 9)
    m = paper_derived.numeric(level_flight)
    phi, gamma = taylor_discretization(m["F"], m["G"], 60.0, 9)
    qd = taylor_process_noise(gamma, m["Q"], 60.0)
    assert np.all(phi[~s.Phi] == 0)
    assert np.all(qd[~s.Qd] == 0)


def test_random_constant_states_are_unit_rows(paper_derived):
    s = filter_structure(paper_derived.structure("F"), paper_derived.structure("G"), paper_derived.structure("H"), 9)
    names = [paper_derived.model.state_names[i] for i in s.unit_rows]
    assert names == [
        "gyro_constant_drift_x",
        "gyro_constant_drift_y",
        "gyro_constant_drift_z",
        "doppler_velocity_bias_north",
        "doppler_velocity_bias_east",
    ]
