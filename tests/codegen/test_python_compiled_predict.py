"""The generated Python module's compiled predict (numba, the [sim] extra) against its numpy path.

With numba installed, predict and Filter.predict first run one compiled kernel over Phi's
structural pattern (``_compiled_predict``); it writes its results only when every check
passes, and otherwise the numpy path decides.  These tests prove that the kernel takes the
usual inputs (else the speed would be the numpy path's), gives the numpy path's numbers
(within rounding, P exactly symmetric), leaves to the numpy path whatever it does not
prove, and keeps the Filter unchanged on a refusal although it updates in place.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.codegen.test_contract import bad_covariances
from tests.codegen.test_python_filter_class import arguments, py, state_of, with_entry  # noqa: F401 (fixtures)

pytest.importorskip("numba")


def close(a, b) -> bool:
    return np.allclose(a, b, rtol=1e-12, atol=1e-14 * np.abs(b).max())


@pytest.fixture
def numpy_path(py):  # noqa: F811
    """The module with the compiled kernel switched off for the test's duration (what runs without numba)."""
    yield py
    py.COMPILED = True


def test_the_compiled_kernel_takes_the_usual_inputs_of_both_apis(py, arguments):  # noqa: F811
    a = arguments
    x, P = np.empty(18), np.empty((18, 18))
    assert py.COMPILED
    assert py._compiled_predict(a["x"], a["P"], a["Phi"], a["Qd"], x, P, True)
    assert py._compiled_predict(a["x"], a["P"], a["Phi"], a["Qd"], x, P, False)


def test_compiled_and_numpy_predicts_give_the_same_numbers(py, numpy_path, arguments):  # noqa: F811
    a = arguments
    results = {}
    for compiled in (True, False):
        py.COMPILED = compiled
        f = py.Filter(a["x"], a["P"])
        f.predict(a["Phi"], a["Qd"])
        results[compiled] = py.predict(a["x"], a["P"], a["Phi"], a["Qd"]), (f.get_state(), f.get_covariance())
    for got, want in zip(results[True], results[False]):
        assert close(got[0], want[0]) and close(got[1], want[1])
        assert np.array_equal(got[1], got[1].T)
    want = a["Phi"] @ a["P"] @ a["Phi"].T + a["Qd"]
    assert close(results[True][0][1], np.triu(want) + np.triu(want, 1).T)


def test_a_phi_nonzero_off_its_pattern_is_left_to_the_numpy_path(py, arguments):  # noqa: F811
    a = arguments
    off = tuple(int(k) for k in np.argwhere(py._KERNEL_OFF_PATTERN)[0])
    Phi = with_entry(a["Phi"], off, 0.25)
    assert not py._compiled_predict(a["x"], a["P"], Phi, a["Qd"], np.empty(18), np.empty((18, 18)), True)
    x_new, P_new = py.predict(a["x"], a["P"], Phi, a["Qd"])
    assert close(x_new, Phi @ a["x"]) and close(P_new, np.triu(Phi @ a["P"] @ Phi.T + a["Qd"]) + np.triu(Phi @ a["P"] @ Phi.T + a["Qd"], 1).T)


@pytest.mark.parametrize("what", list(bad_covariances(18)))
def test_a_covariance_outside_the_contract_is_not_proven_by_the_kernel_and_refused_as_without_it(py, numpy_path, arguments, what):  # noqa: F811
    a, P = arguments, bad_covariances(18)[what]
    assert not py._compiled_predict(a["x"], P, a["Phi"], a["Qd"], np.empty(18), np.empty((18, 18)), True)
    messages = []
    for compiled in (True, False):
        py.COMPILED = compiled
        with pytest.raises(ValueError) as error:
            py.predict(a["x"], P, a["Phi"], a["Qd"])
        messages.append(str(error.value))
    assert messages[0] == messages[1]


@pytest.mark.parametrize("argument, index, value", [("Qd", (4, 4), -1e-9), ("Qd", (9, 2), math.nan), ("Phi", (2, 5), math.inf)])
def test_a_refused_compiled_filter_predict_leaves_the_filter_unchanged(py, arguments, argument, index, value):  # noqa: F811
    a = arguments
    bad = {"Phi": a["Phi"], "Qd": a["Qd"], argument: with_entry(a[argument], index, value)}
    f = py.Filter(a["x"], a["P"])
    before = state_of(f)
    with pytest.raises(ValueError, match=f"predict: {argument}"):
        f.predict(bad["Phi"], bad["Qd"])
    assert state_of(f) == before


def test_a_module_of_the_same_text_takes_the_kernel_already_compiled_and_another_text_its_own(py, arguments, tmp_path):  # noqa: F811
    """load_python_module keeps one compiled kernel per module text in the process (numba compiles on the first
    call, seconds): the same text from another folder shares it, any other text compiles its own."""
    from pathlib import Path

    from modelgen.codegen.build import load_python_module

    text = Path(py.__file__).read_text()
    (tmp_path / "same").mkdir()
    (tmp_path / "same" / "m.py").write_text(text)
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "m.py").write_text(text + "\n# another text\n")
    same, other = load_python_module(tmp_path / "same" / "m.py"), load_python_module(tmp_path / "other" / "m.py")
    assert same is not py and same._compiled_predict is py._compiled_predict
    assert other._compiled_predict is not py._compiled_predict
    a = arguments
    for module in (same, other):
        x, P = np.empty(18), np.empty((18, 18))
        assert module._compiled_predict(a["x"], a["P"], a["Phi"], a["Qd"], x, P, True)
        assert close(x, a["Phi"] @ a["x"]) and np.array_equal(P, P.T)
