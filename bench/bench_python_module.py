#!/usr/bin/env python
"""Benchmark: the generated Python module against plain dense numpy, per call, in one run.

For the paper's 18-state model, the 32-state augmented model and a
100-state augmented model (``tests/codegen/large_model_support``), with the
same inputs for both sides (Phi and Q_d from the reference discretization,
a covariance after ten filter cycles):

Two generated APIs are timed, each against the same numpy sides:

* the *functional* API, ``predict(x, P, Phi, Qd)`` and ``update(x, P, z,
  H, r)``: the caller holds P, so every call proves it against the contract
  (exact symmetry and a LAPACK Cholesky, ``_factor``) before using it;
* the *Filter* class, ``Filter(x, P)`` then ``f.predict(Phi, Qd)`` and
  ``f.update(z, H, r)``: like the generated C's filter struct it owns x and
  P, proves P once (``set_covariance``) and trusts what its own steps made
  of it, testing only that the results are finite (and Phi, Q_d, z, H, r
  as the functional API does).  Each timed call also restores the filter's
  x and P (two attribute assignments) so that every call starts from the
  same P; that cost is counted on the generated side.

The functions:

* ``predict`` -- generated ``predict``, which checks its
  arguments against the contract (finite; P symmetric and positive
  semidefinite, proven by a Cholesky factorization) and the result
  (the Filter: Phi, Q_d and the result), against
  two dense numpy functions computing the same numbers with the same
  symmetrization (upper triangle mirrored into the lower,
  ``np.copyto(..., where=lower)``):

  - *bare*: ``x = Phi @ x``, ``P = Phi @ P @ Phi.T + Qd``, mirrored, no
    checks at all (the issue's baseline);
  - *checked*: the same after the same contract written in plain numpy:
    ``np.isfinite(a).all()`` for every argument, ``np.array_equal(P, P.T)``
    and ``np.linalg.cholesky(P)``, and ``np.isfinite(...).all()`` for the
    results;
* ``update`` -- generated ``update(x, P, z, H, r)`` against dense numpy doing
  the same Kalman update: ``S = H P H^T + R``, ``K = solve(S, H P)^T``,
  the Joseph form ``(P - K H P) - (P - K H P) H^T K^T + K R K^T``, mirrored;
  bare, and checked as predict (plus ``r >= 0``);
* ``discretize`` -- generated ``discretize(F, G, q, T)`` against
  ``modelgen.derivation.discretization`` (the numpy reference: the same balancing,
  order rule, Taylor series and doublings) and ``taylor_process_noise``;
  bare, and checked (finite F, G, q, ``q >= 0``, finite positive T, finite
  results).

Each side is timed best-of-several with interleaved repeats (CPU time of
the process, BLAS on one thread); each ratio is numpy time / generated time
(>= 1: the generated module is at least as fast).  The ``P test`` column is
what the contract's test of P costs inside the generated predict and update
(``_factor``: the exact-symmetry test and the LAPACK Cholesky, timed
alone): the part of the generated time that the bare numpy does not do.
For predict the two kernels the generator chooses between are both
timed, to justify its rules: for the functional API the factored form
(BLAS trmm and syrk on the Cholesky factor of the P test) or by row class
of Phi (D P D elementwise and one product of the general rows),
``kernels.python_predict_kernel``; for the Filter the dense form (M = Phi
P, then one dgemm) or by row class, ``kernels.python_filter_predict_kernel``.  The machine's load (``os.getloadavg``)
is recorded before and after.  Writes bench/results/python_module.json,
.md and .png.

Target (issue 14, item 3): ratio >= 1.0 for predict, update and discretize
at 18, 32 and 100 states (against the bare numpy; the checked ratio shows
what the same contract costs in numpy).  Both APIs' rows are reported.

usage: nice python bench/bench_python_module.py [--sizes 18 32 100] [--kernel-sizes 40 48 64 80]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
import timeit
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads: one core for both sides
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))  # runs from a fresh clone without installing

from modelgen.checks.code_check import measurement_sequence  # noqa: E402
from modelgen.codegen import kernels  # noqa: E402
from modelgen.codegen.build import load_python_module  # noqa: E402
from modelgen.codegen.backends.registry import backend  # noqa: E402
from modelgen.codegen.generate import describe, write_atomically  # noqa: E402
from modelgen.derivation import reference  # noqa: E402
from modelgen.derivation.discretization import DEFAULT_TOLERANCE, taylor_discretization, taylor_process_noise  # noqa: E402
from modelgen.derivation.symbolic import derive  # noqa: E402
from modelgen.jobs import paper_scenario, synthetic_scenario  # noqa: E402
from modelgen.model.loading import load_model  # noqa: E402
from tests.codegen.large_model_support import large_model  # noqa: E402

RESULTS = HERE / "results"
BUILTIN = {18: "ned_doppler18", 32: "ned_doppler32_augmented"}
START = time.perf_counter()
ROUNDS = 5  # interleaved rounds of every side; each round is the best of 7 timeit repeats


def progress(message: str) -> None:
    print(f"[{time.perf_counter() - START:7.1f} s] {message}", flush=True)


def per_call_us(function, repeats: int = 7) -> float:
    """Best CPU time of this process per call in microseconds (timeit, calls batched to about 20 ms).

    CPU time rather than wall time: on a shared machine the wall clock also
    counts the time other processes hold the core (BLAS is kept to one
    thread: OPENBLAS_NUM_THREADS=1 is set before numpy loads).
    """
    timer = timeit.Timer(function, timer=time.process_time)
    number, _ = timer.autorange()
    number = max(1, number // 10)
    return min(timer.repeat(repeats, number)) / number * 1e6


RULES = ("PYTHON_STRUCTURED_SAVING_FLOPS", "PYTHON_FILTER_STRUCTURED_SAVING_FLOPS")  # functional, Filter


def module_for(derived, folder: Path, kernel: str | None):
    """The generated Python module with the default kernel rules (None) or forced predict kernels.

    ``structured``: both APIs by row class; ``dense``: the functional API
    factored (trmm, syrk) and the Filter dense (Phi P, one dgemm).
    """
    saved = {name: getattr(kernels, name) for name in RULES}
    if kernel is not None:
        for name in RULES:
            setattr(kernels, name, -10**12 if kernel == "structured" else 10**15)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            files = backend("python").render(describe(derived))  # the Python module only
    finally:
        for name, value in saved.items():
            setattr(kernels, name, value)
    out = folder / (kernel or "default")
    write_atomically(out, files)
    return load_python_module(out / f"{derived.model.name}.py")


def inputs(derived, scenario) -> dict:
    m = derived.numeric(scenario.parameters)
    T = scenario.step
    phi, gamma = taylor_discretization(m["F"], m["G"], T, 9, tolerance=DEFAULT_TOLERANCE)
    qd = taylor_process_noise(gamma, m["Q"], T)
    x, P = scenario.x0(), scenario.initial_covariance.copy()
    zs = measurement_sequence(derived, scenario)
    for z in zs[:10]:  # a covariance with the filter's real correlations
        x = phi @ x
        P = reference.predict_covariance(P, phi, qd)
        x, P = reference.update(x, P, z, m["H"], m["R"])
    P = 0.5 * (P + P.T)
    return {"F": m["F"], "G": m["G"], "q": np.diag(m["Q"]).copy(), "T": T, "Phi": phi, "Qd": qd, "x": x, "P": P,
            "H": m["H"], "r": np.diag(m["R"]).copy(), "z": zs[10]}


def dense_predict(lower):
    def predict(x, P, Phi, Qd):
        x_new = Phi @ x
        P_new = Phi @ P @ Phi.T + Qd
        np.copyto(P_new, P_new.T, where=lower)
        return x_new, P_new
    return predict


def dense_update(lower):
    def update(x, P, z, H, r):
        HP = H @ P
        S = HP @ H.T + np.diag(r)
        K = np.linalg.solve(S, HP).T
        x_new = x + K @ (z - H @ x)
        B = P - K @ HP
        P_new = B - (B @ H.T) @ K.T + (K * r) @ K.T
        np.copyto(P_new, P_new.T, where=lower)
        return x_new, P_new
    return update


def dense_discretize(F, G, q, T):
    phi, gamma = taylor_discretization(F, G, T, 9, tolerance=DEFAULT_TOLERANCE)
    return phi, taylor_process_noise(gamma, np.diag(q), T)


def require_finite(**arrays) -> None:
    """The contract's finiteness test as plain numpy writes it: one isfinite pass per array."""
    for name, value in arrays.items():
        if not np.isfinite(value).all():
            raise ValueError(f"{name} has a non-finite entry")


def require_covariance(P) -> None:
    """P exactly symmetric and positive definite, proven by numpy's Cholesky (LinAlgError otherwise)."""
    if not np.array_equal(P, P.T):
        raise ValueError("P is not symmetric")
    np.linalg.cholesky(P)


def checked_predict(lower):
    """dense_predict after and before the contract's checks, in plain numpy."""
    bare = dense_predict(lower)

    def predict(x, P, Phi, Qd):
        require_finite(x=x, P=P, Phi=Phi, Qd=Qd)
        require_covariance(P)
        x_new, P_new = bare(x, P, Phi, Qd)
        require_finite(x_result=x_new, result=P_new)
        return x_new, P_new
    return predict


def checked_update(lower):
    """dense_update after and before the contract's checks, in plain numpy."""
    bare = dense_update(lower)

    def update(x, P, z, H, r):
        require_finite(x=x, P=P, z=z, H=H, r=r)
        if not (r >= 0.0).all():
            raise ValueError("r has a negative measurement variance")
        require_covariance(P)
        x_new, P_new = bare(x, P, z, H, r)
        require_finite(x_result=x_new, result=P_new)
        return x_new, P_new
    return update


def checked_discretize(F, G, q, T):
    """dense_discretize after and before the contract's checks, in plain numpy."""
    require_finite(F=F, G=G, q=q)
    if not (q >= 0.0).all():
        raise ValueError("q has a negative noise PSD")
    if not (np.isfinite(T) and T > 0.0):
        raise ValueError("T must be finite and positive")
    phi, qd = dense_discretize(F, G, q, T)
    require_finite(Phi=phi, Qd=qd)
    return phi, qd


#: (API, kernel rule name, first kernel, second kernel): the predict kernels each API chooses between.
KERNELS = (("functional", "python_predict_kernel", "factored", "structured"),
           ("Filter", "python_filter_predict_kernel", "dense", "structured"))
FUNCTIONS = ("predict", "update", "discretize")
APIS = {"predict": ("functional", "Filter"), "update": ("functional", "Filter"), "discretize": ("functional",)}


def filter_calls(module, a: dict):
    """Filter.predict and Filter.update, each restoring x and P after the call (the same start every call)."""
    f = module.Filter(a["x"], a["P"])
    x, P = f.get_state(), f.get_covariance()

    def predict():
        f.predict(a["Phi"], a["Qd"])
        f._x, f._P = x, P  # restored: two attribute assignments, counted on the generated side

    def update():
        f.update(a["z"], a["H"], a["r"])
        f._x, f._P = x, P

    def results(name):
        """The filter's x and P after one call of ``name``, then restored."""
        if name == "predict":
            f.predict(a["Phi"], a["Qd"])
        else:
            f.update(a["z"], a["H"], a["r"])
        out = f.get_state(), f.get_covariance()
        f._x, f._P = x, P
        return out

    return {"predict": predict, "update": update, "results": results}


def kernel_times(derived, a: dict, folder: Path) -> dict:
    """CPU us per call of each API's two predict kernels (forced), the flops the row classes save, the rules' choices."""
    structure = describe(derived).structure
    out = {}
    for kernel in ("dense", "structured"):
        module = module_for(derived, folder, kernel)
        calls = filter_calls(module, a)
        x, P, Phi, Qd = (a[k] for k in ("x", "P", "Phi", "Qd"))
        out["functional", "factored" if kernel == "dense" else kernel] = min(
            per_call_us(lambda: module.predict(x, P, Phi, Qd)) for _ in range(ROUNDS))
        out["Filter", kernel] = min(per_call_us(calls["predict"]) for _ in range(ROUNDS))
    return {"states": derived.n_states,
            "saving_flops": int(kernels.dense_predict_cost(derived.n_states).total - kernels.python_predict_cost(structure).total),
            "chosen": kernels.python_predict_kernel(structure), "filter_chosen": kernels.python_filter_predict_kernel(structure),
            **{f"{api}_{kernel}_us": us for (api, kernel), us in out.items()}}


def measure(n: int, folder: Path) -> dict:
    derived = derive(load_model(BUILTIN[n]) if n in BUILTIN else large_model(n))
    scenario = paper_scenario(derived) if n == 18 else synthetic_scenario(derived)
    a = inputs(derived, scenario)
    lower = np.tril(np.ones((n, n), dtype=bool), -1)
    structure = describe(derived).structure
    chosen = {"functional": kernels.python_predict_kernel(structure), "Filter": kernels.python_filter_predict_kernel(structure)}
    gen = module_for(derived, folder, None)
    calls = filter_calls(gen, a)
    x, P, Phi, Qd, H, r, z = (a[k] for k in ("x", "P", "Phi", "Qd", "H", "r", "z"))
    F, G, q, T = a["F"], a["G"], a["q"], a["T"]
    numpy_sides = {  # bare numpy, checked numpy: the same function
        "predict": (lambda: dense_predict(lower)(x, P, Phi, Qd), lambda: checked_predict(lower)(x, P, Phi, Qd)),
        "update": (lambda: dense_update(lower)(x, P, z, H, r), lambda: checked_update(lower)(x, P, z, H, r)),
        "discretize": (lambda: dense_discretize(F, G, q, T), lambda: checked_discretize(F, G, q, T)),
    }
    generated = {
        ("predict", "functional"): lambda: gen.predict(x, P, Phi, Qd),
        ("update", "functional"): lambda: gen.update(x, P, z, H, r),
        ("discretize", "functional"): lambda: gen.discretize(F, G, q, T),
        ("predict", "Filter"): calls["predict"],
        ("update", "Filter"): calls["update"],
    }
    for (name, api), side in generated.items():  # the same numbers from every side, and P exactly symmetric
        want = numpy_sides[name][0]()
        got = calls["results"](name) if api == "Filter" else side()
        for g, w in zip(list(got) + list(numpy_sides[name][1]()), list(want) * 2):
            assert np.allclose(g, w, rtol=1e-9, atol=1e-12 * np.abs(w).max()), f"{name} ({api}): generated and numpy differ"
        if name != "discretize":
            assert np.array_equal(got[1], got[1].T), f"{name} ({api}): generated P not exactly symmetric"
    row = {"states": n, "model": derived.model.name, "predict_kernel": chosen["functional"],
           "filter_predict_kernel": chosen["Filter"]}
    for name in FUNCTIONS:
        g = {api: float("inf") for api in APIS[name]}
        b = c = float("inf")
        for _ in range(ROUNDS):  # interleaved, so that a busy spell hits every side
            for api in APIS[name]:
                g[api] = min(g[api], per_call_us(generated[name, api]))
            b = min(b, per_call_us(numpy_sides[name][0]))
            c = min(c, per_call_us(numpy_sides[name][1]))
        for api in APIS[name]:
            key = name if api == "functional" else f"{name}_filter"
            row[key] = {"api": api, "generated_us": g[api], "dense_numpy_us": b, "ratio": b / g[api],
                        "checked_numpy_us": c, "checked_ratio": c / g[api]}
            progress(f"{n} states {name} ({api}): generated {g[api]:.1f} us, bare numpy {b:.1f} us (ratio {b / g[api]:.2f}), "
                     f"checked numpy {c:.1f} us (ratio {c / g[api]:.2f})")
    p_test = min(per_call_us(lambda: gen._factor(P)) for _ in range(ROUNDS))
    for name in ("predict", "update"):
        row[name]["p_test_us"] = p_test  # the functional API's; the Filter does not test P per call
    row["predict_kernels"] = kernel_times(derived, a, folder)
    progress(f"{n} states predict kernels: " + ", ".join(f"{k} {v:.1f} us" for k, v in row["predict_kernels"].items()
                                                          if k.endswith("_us"))
             + f"; the rules chose {chosen['functional']} (functional) and {chosen['Filter']} (Filter)")
    return row


def measure_kernels(n: int, folder: Path) -> dict:
    """Each API's two predict kernels alone at an intermediate size (a large_model of n states), for the kernel rules."""
    derived = derive(large_model(n))
    row = kernel_times(derived, inputs(derived, synthetic_scenario(derived)), folder)
    progress(f"{n} states predict kernels: " + ", ".join(f"{k} {v:.1f} us" for k, v in row.items() if k.endswith("_us"))
             + f"; the rules chose {row['chosen']} (functional) and {row['filter_chosen']} (Filter)")
    return row


def kernel_markdown(rows: list[dict]) -> str:
    lines = ["| states | flops the row classes save | functional: factored us | structured us | chosen "
             "| Filter: dense us | structured us | chosen |",
             "|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r['states']} | {r['saving_flops']:,} | {r['functional_factored_us']:.1f} | {r['functional_structured_us']:.1f} "
              f"| {r['chosen']} | {r['Filter_dense_us']:.1f} | {r['Filter_structured_us']:.1f} | {r['filter_chosen']} |"
              for r in rows]
    return "\n".join(lines) + "\n" + kernel_rule_note(rows)


def kernel_rule_note(rows: list[dict]) -> str:
    """Where a rule picks the slower of its two predict kernels (empty when neither does)."""
    wrong = []
    for r in rows:
        for api, rule, first, second in KERNELS:
            chosen = r["chosen"] if api == "functional" else r["filter_chosen"]
            other = second if chosen == first else first
            chosen_us, other_us = r[f"{api}_{chosen}_us"], r[f"{api}_{other}_us"]
            if other_us < chosen_us:
                wrong.append(f"{r['states']} states, {api} ({other} {other_us:.1f} us against {chosen} {chosen_us:.1f}; "
                             f"`kernels.{rule}`)")
    if not wrong:
        return ""
    return "\nA rule picks the slower kernel at " + ", ".join(wrong) + ".\n"


def markdown(rows: list[dict]) -> str:
    lines = ["| states | function | API | generated us | bare numpy us | ratio to bare | checked numpy us "
             "| ratio to checked | P test us | predict kernels us | chosen |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        k = r["predict_kernels"]
        for name in FUNCTIONS:
            for api in APIS[name]:
                c = r[name if api == "functional" else f"{name}_filter"]
                kernel = chosen = ""
                if name == "predict":
                    first, chosen = ("factored", r["predict_kernel"]) if api == "functional" else ("dense", r["filter_predict_kernel"])
                    kernel = f"{first} {k[f'{api}_{first}_us']:.1f}, structured {k[f'{api}_structured_us']:.1f}"
                test = f"{c['p_test_us']:.1f}" if "p_test_us" in c else ("none (trusted)" if api == "Filter" else "")
                lines.append(f"| {r['states']} | {name} | {api} | {c['generated_us']:.1f} | {c['dense_numpy_us']:.1f} "
                             f"| {c['ratio']:.2f} | {c['checked_numpy_us']:.1f} | {c['checked_ratio']:.2f} | {test} | {kernel} | {chosen} |")
    return "\n".join(lines) + "\n"


LEGEND = """All times are CPU time per call (best of {rounds} interleaved rounds, each the best of 7 timeit
repeats; BLAS on one thread).  Every side computes the same function on the same inputs (Phi and Q_d
from the reference discretization, P after ten filter cycles) and returns the same numbers, P exactly
symmetric (upper triangle mirrored):

* generated, functional API (`predict(x, P, Phi, Qd)`, `update(x, P, z, H, r)`, `discretize`): the caller
  holds P, so every call proves it against the contract (P exactly symmetric and positive definite by a
  Cholesky factor, else entry by entry within 16 N eps), and checks finite arguments and results, r, q >= 0;
* generated, Filter class (`f.predict(Phi, Qd)`, `f.update(z, H, r)`), the generated C's API: the filter
  owns x and P, proves P once (constructor, `set_covariance`, not timed) and trusts what its own steps
  made of it, as the C does; it checks Phi, Q_d, z, H, r (finite, r >= 0) and finite results like the
  functional API.  Its time includes restoring x and P after each call (two attribute assignments);
* bare numpy: the same products with no checks at all (`Phi @ P @ Phi.T + Qd`; the Joseph update with
  `np.linalg.solve`; `modelgen.derivation.discretization` for discretize) -- the issue's baseline;
* checked numpy: bare numpy plus the functional API's contract in plain numpy (`np.isfinite(a).all()`
  per argument and result, `np.array_equal(P, P.T)`, `np.linalg.cholesky(P)`, `r >= 0` / `q >= 0`).

ratio = numpy time / generated time (>= 1: the generated side is at least as fast).  P test: the
functional API's test of P alone (`_factor`: exact symmetry and LAPACK dpotrf), which neither the bare
numpy nor the Filter does per call.  Predict kernels, each timed with the other forced: for the
functional API the factored form (BLAS trmm and syrk on the Cholesky factor) or by row class (D P D
elementwise plus one product of the general rows of Phi), chosen by `kernels.python_predict_kernel`;
for the Filter the dense form (M = Phi P, then one dgemm M Phi^T + Q_d on Fortran views) or by row
class, chosen by `kernels.python_filter_predict_kernel`.  The generated update forms the Joseph
covariance as P - (G + G^T) with G = K (H P - S K^T / 2): one product of rank m (the measurements),
exactly symmetric without a mirroring pass; the Filter's is the same code, bit for bit.  The finiteness
of the results is one BLAS dasum (sum of magnitudes) each.
"""


def misses_note(rows: list[dict]) -> str:
    """Each ratio below 1.0 to the bare numpy, per API, with what the functional API's test of P alone costs there."""
    misses = []
    for r in rows:
        for name in FUNCTIONS:
            for api in APIS[name]:
                c = r[name if api == "functional" else f"{name}_filter"]
                if c["ratio"] < 1.0:
                    test = (f"; its test of P alone takes {c['p_test_us']:.1f} us, {c['p_test_us'] / c['dense_numpy_us']:.0%} "
                            f"of the bare numpy time, and the rest {c['generated_us'] - c['p_test_us']:.1f} us"
                            if "p_test_us" in c else "")
                    misses.append(f"* {r['states']} states {name}, {api} API: {c['generated_us']:.1f} us against "
                                  f"{c['dense_numpy_us']:.1f} us (ratio {c['ratio']:.2f}){test}.")
    if not misses:
        return "\nEvery ratio to the bare numpy is at least 1.0, for both APIs.\n"
    return "\nBelow 1.0 to the bare numpy (which checks nothing):\n\n" + "\n".join(misses) + "\n"


def figure(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8.5, 5))
    groups = [(name, api) for name in FUNCTIONS for api in APIS[name]]
    width = 0.8 / len(rows)
    for k, r in enumerate(rows):
        at = np.arange(len(groups)) + k * width
        cells = [r[name if api == "functional" else f"{name}_filter"] for name, api in groups]
        bars = ax.bar(at, [c["ratio"] for c in cells], width, label=f"{r['states']} states: to bare numpy")
        ax.scatter(at, [c["checked_ratio"] for c in cells], marker="D", s=25, color=bars[0].get_facecolor(),
                   edgecolors="black", zorder=3, label=f"{r['states']} states: to checked numpy")
    ax.axhline(1.0, color="gray", linestyle=":", label="as fast as numpy")
    ax.set_xticks(np.arange(len(groups)) + width * (len(rows) - 1) / 2, [f"{name}\n({api})" for name, api in groups])
    ax.set_ylabel("numpy time / generated time [-]")
    ax.set_title("generated Python module against dense numpy (per call, same function)")
    ax.legend(fontsize=7, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.15))  # below the axes: no bar hidden
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[18, 32, 100])
    parser.add_argument("--kernel-sizes", type=int, nargs="*", default=[40, 48, 64, 80],
                        help="intermediate sizes (above 32) where only the two predict kernels are timed")
    args = parser.parse_args()
    RESULTS.mkdir(exist_ok=True)
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        rows = [measure(n, Path(tmp)) for n in args.sizes]
        kernel_rows = [measure_kernels(n, Path(tmp)) for n in args.kernel_sizes]
    load_after = os.getloadavg()
    load = (f"Load average (1, 5, 15 min) on {os.cpu_count()} cores: {' '.join(f'{v:.2f}' for v in load_before)} "
            f"before, {' '.join(f'{v:.2f}' for v in load_after)} after the run.")
    table = markdown(rows)
    (RESULTS / "python_module.json").write_text(
        json.dumps({"load_before": load_before, "load_after": load_after, "cores": os.cpu_count(), "rows": rows,
                    "predict_kernels": kernel_rows},
                   indent=2) + "\n")
    (RESULTS / "python_module.md").write_text(
        "# Generated Python module against dense numpy (bench/bench_python_module.py)\n\n"
        + LEGEND.format(rounds=ROUNDS) + "\n" + load + "\n\n" + table + misses_note(rows)
        + "\n## The predict kernels of both APIs at every size (CPU time per call; between 32 and 100 states a large_model)\n\n"
        + kernel_markdown(sorted([r["predict_kernels"] for r in rows] + kernel_rows, key=lambda r: r["states"])))
    progress(load)
    figure(rows, RESULTS / "python_module.png")
    print(table)
    progress(f"wrote {RESULTS / 'python_module.json'}, .md and .png")


if __name__ == "__main__":
    main()
