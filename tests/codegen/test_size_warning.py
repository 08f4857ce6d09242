"""Large models are announced: a warning gives the expected size of the generated code before it is built."""

import warnings

import numpy as np
import pytest

from modelgen.codegen import generate as generate_module
from modelgen.codegen.generate import GeneratedSizeWarning, LARGE_CODE_BYTES, generate_code, warn_if_large
from modelgen.codegen.kernels import estimated_code_bytes
from modelgen.codegen.structure import filter_structure


def structure_of(derived):
    return filter_structure(derived.structure("F"), derived.structure("G"), derived.structure("H"), 9)


@pytest.mark.parametrize("name", ["ned_doppler18", "ned_doppler32_augmented"])
def test_estimate_is_within_a_quarter_of_what_is_written(name, derived_builtin):
    derived = derived_builtin(name)
    written = sum(len(text) for text in generate_code(derived).files.values())
    assert abs(estimated_code_bytes(structure_of(derived)) / written - 1) < 0.25


def test_the_paper_model_is_not_large(paper_derived):
    with warnings.catch_warnings():
        warnings.simplefilter("error", GeneratedSizeWarning)
        generate_code(paper_derived)


def test_a_dense_hundred_state_model_is_announced_with_its_size():
    n = 100  # compact kernels: its size comes from the 10,000 expressions of a dense F
    structure = filter_structure(np.ones((n, n), bool), np.eye(n, dtype=bool), np.zeros((0, n), bool), 9)
    assert estimated_code_bytes(structure) > LARGE_CODE_BYTES
    with pytest.warns(GeneratedSizeWarning, match=r"'big' is large: its generated code will be about \d+\.\d MB .*100 states.*2 MB"):
        warn_if_large("big", structure)


def test_generate_warns_before_building_when_above_the_threshold(paper_derived, monkeypatch):
    monkeypatch.setattr(generate_module, "LARGE_CODE_BYTES", 100_000)
    with pytest.warns(GeneratedSizeWarning, match=r"about 0\.3 MB"):
        generate_code(paper_derived)
