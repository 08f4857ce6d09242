#!/usr/bin/env python
"""Benchmark: the whole filter cycle of modelgen's generated C against CasADi and SymForce.

One command (from the repository root):

    python bench/bench_cycle.py                     # 18, 32 and 100 states, all tools
    python bench/bench_cycle.py --skip-symforce     # without the SymForce venv

writes bench/results/cycle.json, cycle.md and cycle.png and prints the
table (``--report-only`` redraws the table and figure from cycle.json).  What each side computes, per call, for the same model, operating
point and covariance:

(a) prediction with Phi and Q_d given: x' = Phi x, P' = Phi P Phi^T + Q_d
    (bench/bench_codegen.py's comparison: the tools get symbols only at the
    structural nonzeros of Phi and Q_d, and a symmetric P);
(b) the full predict cycle from continuous parameters: (parameters, T, P, x)
    -> (P', x') with F, G, Q evaluated from the parameters, Phi and
    Gamma by the Taylor series of eqs. (10)-(11) of the same order as
    modelgen sums it (S = sum (F T)^k / (k+1)! by Horner's rule, Phi = I + F T S,
    Gamma = T S G: modelgen.derivation.discretization), Q_d =
    Gamma (Q/T) Gamma^T and the prediction.  CasADi and SymForce are given
    the model's F, G, diag(Q) as symbolic expressions of the parameters
    (CasADi from modelgen.derivation.casadi_functions, SymForce from their
    text, read by symengine) and generate that one function symbolically, P packed upper in and
    out.  modelgen's side is its generated matrices_evaluate + discretize +
    predict (default options: full symmetric storage, computed once per
    pair), which also computes ||F||_D (D fixed at generation time, F rebalanced at run time when
    that plan needs a doubling) and chooses the order and doublings at run time
    (modelgen.derivation.discretization.step_plan): the order and doublings the competitors get are
    the one that rule picks at that T (T = 60 s: 9, the paper's; T = 1 s: 5 for the
    paper's model), so both sides sum the same series;
(c) the measurement update (vector update, Joseph form; the tools: the
    textbook Joseph update of bench/bench_codegen.py).

Measured: instructions per call (valgrind's callgrind: deterministic on a
busy machine), wall time per call (best of three runs), storage (what each
implementation keeps between calls beyond its inputs: filter state, scratch,
for (b) also the parameters, model matrices and transition that modelgen
keeps in structs) and the peak stack of one call (stack painting, bench/harness.c).
Beside each row: the sparsity flop floor, the floating-point operations that
the structure leaves (structural nonzeros only, each symmetric pair once,
CSE of the model matrices as modelgen counts it), and the ratios to it and
to the best other tool.

SymForce is not a dependency of modelgen: on first use this script creates
bench/.venv and installs it there (``python -m venv bench/.venv;
bench/.venv/bin/pip install symforce numpy``); its C++ needs Eigen (Debian:
``apt-get install libeigen3-dev``).  At 100 states only CasADi and modelgen run
the full cycle (SymForce's symbolic order-9 series takes too long there);
--symforce-max-states changes that.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import bench_codegen as bc  # noqa: E402

from modelgen.checks.code_check import measurement_sequence  # noqa: E402
from modelgen.codegen.description import EVALUATE  # noqa: E402
from modelgen.codegen.discretize_kernels import (  # noqa: E402
    DiscretizePlan,
    doubling_block,
    noise_blocks,
    scalar_statements,
    structural_series_cost,
)
from modelgen.codegen.generate import describe, generate_code, write_atomically  # noqa: E402
from modelgen.codegen.kernels import OperationCount, update_cost  # noqa: E402
from modelgen.codegen.options import CodegenOptions  # noqa: E402
from modelgen.derivation import reference  # noqa: E402
from modelgen.derivation.discretization import (  # noqa: E402
    DEFAULT_TOLERANCE,
    nominal_scaling,
    step_plan,
    taylor_discretization,
    taylor_process_noise,
)
from modelgen.derivation.symbolic import DerivedModel, derive  # noqa: E402
from modelgen.jobs import paper_scenario, synthetic_scenario  # noqa: E402
from modelgen.model.loading import load_model  # noqa: E402

RESULTS = HERE / "results"
MODELS = ("ned_doppler18", "ned_doppler32_augmented", "ned_doppler100_large")


# -- the problems -------------------------------------------------------------------
def derived_model(name: str) -> DerivedModel:
    """A built-in model, or ``ned_doppler<N>_large``: the augmented model grown to N states (tests/codegen)."""
    if name.endswith("_large"):
        sys.path.insert(0, str(HERE.parent))
        from tests.codegen.large_model_support import large_model

        return derive(large_model(int(name.removeprefix("ned_doppler").removesuffix("_large"))))
    return derive(load_model(name))


def problem(name: str) -> dict:
    """Model, operating point, a covariance with the filter's correlations, and the steps to time."""
    derived = derived_model(name)
    scenario = paper_scenario(derived) if name == "ned_doppler18" else synthetic_scenario(derived)
    m = derived.numeric(scenario.parameters)
    phi, gamma = taylor_discretization(m["F"], m["G"], scenario.step, 9, DEFAULT_TOLERANCE, nominal_scaling(derived))
    qd = taylor_process_noise(gamma, m["Q"], scenario.step)
    x, P = scenario.x0(), scenario.initial_covariance.copy()
    zs = measurement_sequence(derived, scenario)
    for z in zs[:10]:
        x = phi @ x
        P = reference.predict_covariance(P, phi, qd)
        x, P = reference.update(x, P, z, m["H"], m["R"])
    long_step = scenario.step
    steps = [(long_step, "paper's step" if name == "ned_doppler18" else "check step"), (long_step / 60, "step / 60")]
    values = {p.name: float(v) for p, v in zip(derived.model.parameters, _parameter_values(derived, scenario.parameters))}
    description = describe(derived, CodegenOptions())
    return {"name": name, "derived": derived, "description": description, "structure": description.structure,
            "Phi": phi, "Qd": qd, "P": P, "x": x, "H": m["H"], "r": np.diag(m["R"]).copy(), "z": zs[10],
            "n": derived.n_states, "m": derived.n_measurements, "F": m["F"], "values": values, "steps": steps}


def _parameter_values(derived: DerivedModel, values: dict) -> list[float]:
    from modelgen.derivation.symbolic import parameter_vector

    return list(parameter_vector(derived.model, values))


# -- floors ------------------------------------------------------------------------------
def _count(blocks) -> OperationCount:
    """Flops of the blocks' statements, a segment loop counted as the scalar statements it stands for."""
    mul = add = 0
    for b in blocks:
        for s in scalar_statements(b.block.statements):
            mul += sum(len(t) - 1 for t in s.terms)
            add += max(len(s.terms) - 1, 0)
    return OperationCount(mul, add)


def predict_floor(structure) -> int:
    """Flops of x' = Phi x and the upper triangle of Phi P Phi^T + Q_d over the structural nonzeros.

    M = Phi P for rows of Phi that are not e_i (2 nnz - 1 per entry), then each
    pair i <= j of M Phi^T once (2 nnz_j - 1, none for a unit row j) plus the
    Q_d entry where it can be nonzero.
    """
    n = structure.n_states
    unit = set(structure.unit_rows)
    rows = structure.rows("Phi")
    flops = sum(2 * len(rows[i]) - 1 for i in range(n) if i not in unit)
    flops += sum(n * (2 * len(rows[i]) - 1) for i in range(n) if i not in unit)
    for i in range(n):
        for j in range(i, n):
            flops += 0 if j in unit else 2 * len(rows[j]) - 1
            flops += 1 if structure.Qd[i, j] else 0
    return flops


def discretize_floor(structure, order: int, halvings: int) -> int:
    """Flops of Phi and Q_d by Horner's rule of ``order`` over the structural nonzeros of each level (no norm, no plan)."""
    plan = DiscretizePlan(structure, 9)
    noise = _count(noise_blocks(plan, packed=False, ud=False)).total if plan.gamma_entries and plan.qd_pairs else 0
    return structural_series_cost(plan, order).total + noise + halvings * _count([doubling_block(plan)]).total


def floors(p: dict, order: int, halvings: int) -> dict[str, int]:
    description = p["description"]
    evaluate = description.costs[EVALUATE].multiplications
    predict = predict_floor(p["structure"])
    return {
        "a": predict,
        "b": evaluate + discretize_floor(p["structure"], order, halvings) + predict,
        "c": update_cost(p["structure"], CodegenOptions()).total,
    }


# -- glue --------------------------------------------------------------------------------
def c_double(v: float) -> str:
    return repr(float(v))


def glue_generated_cycle(p: dict, T: float, packed: bool = False) -> str:
    """modelgen's glue of the cycle (b); ``packed``: the build with P stored as its packed upper triangle, as the
    anchors take and return it (their memory is then compared with the same storage)."""
    model = p["derived"].model.name
    sets = "\n".join(f"    params.{k} = {c_double(v)};" for k, v in p["values"].items())
    load_p = _packed_p(p["n"], "filt.P") if packed else "    memcpy(filt.P, in_P, sizeof in_P);"
    first_p = "filt.P[0]" if packed else "filt.P[0][0]"
    return f"""#include "{model}.h"
static {model}_params params;
static {model}_matrices mat;
static {model}_transition tr;
static {model}_filter filt, saved;
static {model}_workspace ws;
static void setup(void)
{{
    {model}_default_params(&params);
{sets}
    memcpy(filt.x, in_x, sizeof in_x);
{load_p}
    saved = filt;
}}
static void restore(void) {{ filt = saved; }}
__attribute__((noinline)) void bench_predict_once(void)
{{
    if ({model}_matrices_evaluate(&params, &mat) || {model}_discretize(&mat, {c_double(T)}, &tr, &ws) || {model}_predict(&filt, &tr, &ws)) abort();
}}
__attribute__((noinline)) void bench_update_once(void) {{ abort(); }}
static double checksum(void) {{ return {first_p} + filt.x[0]; }}
static unsigned long storage_bytes(void) {{ return (unsigned long)(sizeof params + sizeof mat + sizeof tr + sizeof filt + sizeof ws); }}
"""


def _packed_p(n: int, array: str) -> str:
    pairs = [(i, j) for i in range(n) for j in range(i, n)]
    return "\n".join(f"    {array}[{k}] = in_P[{i}][{j}];" for k, (i, j) in enumerate(pairs))


def casadi_cycle(p: dict, order: int, folder: Path) -> dict:
    """CasADi's C of the whole cycle (module docstring (b)); returns its work sizes and generation time."""
    import casadi as ca
    import sympy as sp

    from modelgen.derivation.casadi_functions import build_casadi_model, sympy_to_casadi

    start = time.perf_counter()
    derived = p["derived"]
    model = derived.model
    cm = build_casadi_model(model)
    n, nw = derived.n_states, derived.n_noises
    symbols = {q.sym: cm.p[k] for k, q in enumerate(model.parameters)}
    q = [sympy_to_casadi(derived.Q[k, k], symbols, "Q") for k in range(nw)]
    T = ca.SX.sym("T")
    packed = ca.SX.sym("P", n * (n + 1) // 2)
    x = ca.SX.sym("x", n)
    P = ca.SX(n, n)
    k = 0
    for i in range(n):
        for j in range(i, n):
            P[i, j] = packed[k]
            P[j, i] = packed[k]
            k += 1
    X = cm.F * T
    S = ca.SX.eye(n) / math.factorial(order + 1)  # Horner: S = R_0, R_k = I / (k+1)! + X R_(k+1), as modelgen sums it
    for k in range(order - 1, -1, -1):
        S = ca.mtimes(X, S) + ca.SX.eye(n) / math.factorial(k + 1)
    Phi = ca.SX.eye(n) + ca.mtimes(X, S)
    Gamma = T * ca.mtimes(S, cm.G)
    Qd = ca.mtimes([Gamma, ca.diag(ca.vertcat(*q) / T), Gamma.T]) if nw else ca.SX(n, n)
    Pn = ca.mtimes([Phi, P, Phi.T]) + Qd
    upper = ca.vertcat(*[Pn[i, j] for i in range(n) for j in range(i, n)])
    outs = [upper, ca.mtimes(Phi, x)]
    if hasattr(ca, "cse"):
        outs = [ca.cse(o) for o in outs]
    name = f"kf{n}"
    f = ca.Function(f"{name}_cycle", [cm.p, T, packed, x], outs)
    cg = ca.CodeGenerator(f"casadi_{name}_cycle.c", {"with_header": True})
    cg.add(f)
    cg.generate(str(folder) + "/")
    del sp
    return {"seconds": time.perf_counter() - start, "name": name,
            **{k: getattr(f, f"sz_{k}")() for k in ("arg", "res", "iw", "w")}}


def glue_casadi_cycle(p: dict, T: float, info: dict) -> str:
    n = p["n"]
    npk = n * (n + 1) // 2
    name = info["name"]
    params = ", ".join(c_double(v) for v in p["values"].values()) or "0.0"
    return f"""#include "casadi_{name}_cycle.h"
static casadi_real par_v[{max(len(p['values']), 1)}] = {{ {params} }};
static casadi_real t_v = {c_double(T)};
static casadi_real p_v[{npk}], pn_v[{npk}], x_v[BENCH_N], xn_v[BENCH_N];
static casadi_int iw[{info['iw'] + 1}];
static casadi_real w[{info['w'] + 1}];
static const casadi_real *arg[{info['arg'] + 1}];
static casadi_real *res[{info['res'] + 1}];
static void setup(void)
{{
{_packed_p(n, 'p_v')}
    memcpy(x_v, in_x, sizeof x_v);
    arg[0] = par_v; arg[1] = &t_v; arg[2] = p_v; arg[3] = x_v;
    res[0] = pn_v; res[1] = xn_v;
}}
static void restore(void) {{ }}
__attribute__((noinline)) void bench_predict_once(void) {{ {name}_cycle(arg, res, iw, w, 0); }}
__attribute__((noinline)) void bench_update_once(void) {{ abort(); }}
static double checksum(void) {{ return pn_v[0] + xn_v[0]; }}
static unsigned long storage_bytes(void) {{ return (unsigned long)(sizeof par_v + sizeof p_v + sizeof pn_v + sizeof x_v + sizeof xn_v + sizeof iw + sizeof w); }}
"""


def symforce_cycle(python: Path, p: dict, order: int, folder: Path) -> float:
    """SymForce's C++ of the whole cycle (bench/symforce_cycle.py in bench/.venv); returns generation seconds."""
    derived = p["derived"]
    model = derived.model
    rename = {q.sym: f"p{k}" for k, q in enumerate(model.parameters)}
    import sympy as sp

    names = {s: sp.Symbol(v) for s, v in rename.items()}

    def text(expr) -> str:
        return str(sp.sympify(expr).xreplace(names))

    F, G = derived.F, derived.G
    spec = {
        "name": f"kf{p['n']}", "n": p["n"], "nw": derived.n_noises, "order": order, "n_params": len(model.parameters),
        "F": [(i, j, text(F[i, j])) for i, j in p["structure"].entries("F")],
        "G": [(i, j, text(G[i, j])) for i, j in p["structure"].entries("G")],
        "q": [text(derived.Q[k, k]) for k in range(derived.n_noises)],
    }
    (folder / "spec.json").write_text(json.dumps(spec))
    out = bc.run([str(python), str(HERE / "symforce_cycle.py"), str(folder / "spec.json"), str(folder)], timeout=3600)
    return json.loads(out.stdout.strip().splitlines()[-1])["cycle"]


def glue_symforce_cycle(p: dict, T: float) -> str:
    n = p["n"]
    npk = n * (n + 1) // 2
    name = f"kf{n}"
    camel = "".join(part.capitalize() for part in f"{name}_cycle".split("_"))
    values = list(p["values"].values())
    sets = "\n".join(f"    par_v[{k}] = {c_double(v)};" for k, v in enumerate(values))
    return f"""#include <Eigen/Core>
#include "{name}_cycle.h"
static Eigen::Matrix<double, {max(len(values), 1)}, 1> par_v;
static Eigen::Matrix<double, {npk}, 1> p_v, pn_v;
static Eigen::Matrix<double, BENCH_N, 1> x_v, xn_v;
static void setup(void)
{{
{sets}
{_packed_p(n, 'p_v')}
    for (int i = 0; i < BENCH_N; ++i) x_v[i] = in_x[i];
}}
static void restore(void) {{ }}
extern "C" __attribute__((noinline)) void bench_predict_once(void) {{ sym::{camel}<double>(par_v, {c_double(T)}, p_v, x_v, &pn_v, &xn_v); }}
extern "C" __attribute__((noinline)) void bench_update_once(void) {{ abort(); }}
static double checksum(void) {{ return pn_v[0] + xn_v[0]; }}
static unsigned long storage_bytes(void) {{ return (unsigned long)(sizeof par_v + sizeof p_v + sizeof pn_v + sizeof x_v + sizeof xn_v); }}
"""


# -- measurement ---------------------------------------------------------------------------
def measure(exe: Path, data: Path, what: str) -> dict:
    stack, storage = bc.memory_bytes(exe, data, what)
    return {"instructions": bc.callgrind_instructions(exe, data, what), "wall_ns": bc.wall_ns(exe, data, what),
            "storage_bytes": storage, "stack_bytes": stack}


def run_model(name: str, root: Path, sf_python: Path | None, symforce_max: int) -> list[dict]:
    bc.progress(f"{name}: deriving and setting up the problem")
    p = problem(name)
    work = root / name
    work.mkdir()
    data = bc.input_file(p, work)
    rows = []
    gen = work / "modelgen"
    write_atomically(gen, generate_code(p["derived"]).files)
    gen_packed = work / "modelgen-packed"  # P packed, as the anchors' function takes it (the memory comparison)
    write_atomically(gen_packed, generate_code(p["derived"], CodegenOptions(storage="packed")).files)
    model = p["derived"].model.name
    with_symforce = sf_python is not None and p["n"] <= symforce_max

    # (a) and (c): Phi, Q_d given, and the update (bench/bench_codegen.py's glue)
    sp_ = bc.spec(p)
    (work / "casadi").mkdir()
    _, casadi_sizes = bc.casadi_codegen(sp_, work / "casadi")
    builds = {"modelgen": bc.build_harness(_fresh(work, "a-modelgen"), bc.glue_generated(model), [gen / f"{model}.c"], p, includes=(gen,)),
              "casadi": bc.build_harness(_fresh(work, "a-casadi"), bc.glue_casadi(sp_, casadi_sizes),
                                         [work / "casadi" / f"casadi_{sp_['name']}.c"], p, includes=(work / "casadi",))}
    if with_symforce:
        (work / "symforce").mkdir()
        bc.symforce_codegen(sf_python, sp_, work / "symforce")
        builds["symforce"] = bc.build_harness(_fresh(work, "a-symforce"), bc.glue_symforce(sp_), [], p, cxx=True,
                                              includes=(work / "symforce", bc.EIGEN))
    scaling = nominal_scaling(p["derived"])  # the D the generated code bakes in (rebalanced when a doubling is at stake)
    for part, what in (("a", "predict"), ("c", "update")):
        floor = floors(p, 9, 0)[part]
        for impl, exe in builds.items():
            bc.progress(f"{name}: ({part}) {what}: {impl}")
            rows.append({"model": name, "n": p["n"], "part": part, "T": None, "order": None, "impl": impl,
                         "floor_flops": floor, **measure(exe, data, what)})

    # (b) the full cycle at two steps
    for T, label in p["steps"]:
        halvings, order = step_plan(p["F"], T, 9, DEFAULT_TOLERANCE, scaling)  # what the generated code chooses at run time
        floor = floors(p, order, halvings)["b"]
        exes = {"modelgen": bc.build_harness(_fresh(work, f"b-modelgen-{T}"), glue_generated_cycle(p, T), [gen / f"{model}.c"], p,
                                             includes=(gen,)),
                PACKED_IMPL: bc.build_harness(_fresh(work, f"b-modelgen-packed-{T}"), glue_generated_cycle(p, T, packed=True),
                                              [gen_packed / f"{model}.c"], p, includes=(gen_packed,))}
        bc.progress(f"{name}: (b) CasADi cycle, T = {T:g} s, order {order}")
        cfolder = _fresh(work, f"casadi-cycle-{T}")
        info = casadi_cycle(p, order, cfolder)
        exes["casadi"] = bc.build_harness(_fresh(work, f"b-casadi-{T}"), glue_casadi_cycle(p, T, info),
                                          [cfolder / f"casadi_{info['name']}_cycle.c"], p, includes=(cfolder,))
        if with_symforce:
            bc.progress(f"{name}: (b) SymForce cycle, T = {T:g} s, order {order}")
            sfolder = _fresh(work, f"symforce-cycle-{T}")
            try:
                symforce_cycle(sf_python, p, order, sfolder)
                exes["symforce"] = bc.build_harness(_fresh(work, f"b-symforce-{T}"), glue_symforce_cycle(p, T), [], p, cxx=True,
                                                    includes=(sfolder, bc.EIGEN))
            except (RuntimeError, subprocess.TimeoutExpired) as exc:
                bc.progress(f"SymForce cycle failed: {str(exc)[:300]}")
        for impl, exe in exes.items():
            bc.progress(f"{name}: (b) cycle T = {T:g} s: {impl}")
            rows.append({"model": name, "n": p["n"], "part": "b", "T": T, "step": label, "order": order, "halvings": halvings,
                         "impl": impl, "floor_flops": floor, **measure(exe, data, "predict")})
    return rows


def _fresh(work: Path, name: str) -> Path:
    folder = work / name
    folder.mkdir()
    return folder


# -- report ----------------------------------------------------------------------------------
#: modelgen's (b) build with P packed, the same storage as the anchors' cycle functions.
PACKED_IMPL = "modelgen packed P"
PARTS = {"a": "(a) predict, Phi and Q_d given", "b": "(b) full predict cycle from parameters", "c": "(c) update"}


def markdown(rows: list[dict]) -> str:
    lines = [
        "# Whole-cycle benchmark (bench/bench_cycle.py)",
        "",
        f"gcc {bc.OPT}, double, x86-64 ({platform.processor() or platform.machine()}); instructions by callgrind per call;"
        " memory = storage + peak stack of one call.",
        "`vs best` is modelgen's instructions over the best of CasADi and SymForce in the same group;"
        " `Ir/floor` is instructions per flop of the sparsity floor.",
        f"`{PACKED_IMPL}`: modelgen's build with `storage: packed`, P in and out as its packed upper triangle, as the"
        " CasADi and SymForce cycles take and return it (the default `modelgen` row stores P full).",
        "Peak stack is of the second call (bench/harness.c): the first call's lazy binding of libm by the dynamic"
        " linker is not counted on any side.",
        "",
        "| model | part | T [s] | order | impl | instructions | floor flops | Ir/floor | vs best | wall [ns] | storage [B] | stack [B] | memory [B] |",
        "|---|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["model"], r["part"], r["T"]), []).append(r)
    for key, group in groups.items():
        others = [r["instructions"] for r in group if not r["impl"].startswith("modelgen")]
        best = min(others) if others else None
        for r in group:
            ratio = f"{r['instructions'] / best:.3f}" if best and r["impl"].startswith("modelgen") else ""
            T = f"{r['T']:g}" if r["T"] is not None else "-"
            order = str(r["order"]) + (f" (s={r['halvings']})" if r.get("halvings") else "") if r["order"] else "-"
            lines.append(
                f"| {r['model']} | {r['part']} | {T} | {order} | {r['impl']} | {r['instructions']:.0f} | {r['floor_flops']} | "
                f"{r['instructions'] / r['floor_flops']:.2f} | {ratio} | {r['wall_ns']:.0f} | {r['storage_bytes']} | "
                f"{r['stack_bytes']} | {r['storage_bytes'] + r['stack_bytes']} |"
            )
    lines += ["", "Parts: " + "; ".join(f"{k}: {v}" for k, v in PARTS.items()) + "."]
    return "\n".join(lines) + "\n"


def figure(rows: list[dict], path: Path) -> None:
    """Instructions per call of each implementation, one group per (model, part, step), with the flop floor marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups: dict[str, list[dict]] = {}
    for r in rows:
        label = f"{r['model'].replace('ned_doppler', 'n')} ({r['part']})" + (f" T={r['T']:g}s o{r['order']}" if r["T"] else "")
        groups.setdefault(label, []).append(r)
    impls = ["modelgen", "casadi", "symforce"]
    fig, ax = plt.subplots(figsize=(max(8, 1.2 * len(groups)), 4.5))
    width = 0.27
    for k, impl in enumerate(impls):
        xs = [g + (k - 1) * width for g, group in enumerate(groups.values()) if any(r["impl"] == impl for r in group)]
        ys = [next(r["instructions"] for r in group if r["impl"] == impl) for group in groups.values()
              if any(r["impl"] == impl for r in group)]
        ax.bar(xs, ys, width, label=impl)
    for g, group in enumerate(groups.values()):
        ax.hlines(group[0]["floor_flops"], g - 1.5 * width, g + 1.5 * width, colors="k", linestyles="dashed",
                  label="sparsity flop floor" if g == 0 else None)
    ax.set_xticks(range(len(groups)), list(groups), rotation=30, ha="right", fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("instructions per call (callgrind) / flops")
    ax.set_title("Whole filter cycle: (a) predict given Phi, Q_d; (b) parameters -> P'; (c) update")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--models", nargs="+", default=list(MODELS))
    parser.add_argument("--skip-symforce", action="store_true")
    parser.add_argument("--symforce-max-states", type=int, default=32)
    parser.add_argument("--report-only", action="store_true", help="only rewrite cycle.md and cycle.png from cycle.json")
    args = parser.parse_args()
    if args.report_only:
        rows = json.loads((RESULTS / "cycle.json").read_text())
        (RESULTS / "cycle.md").write_text(markdown(rows))
        figure(rows, RESULTS / "cycle.png")
        return 0
    sf_python = None
    if not args.skip_symforce:
        sf_python = bc.symforce_python()
        if sf_python is not None and not bc.eigen_available():
            bc.progress("Eigen headers missing (apt-get install libeigen3-dev): skipping SymForce")
            sf_python = None
    rows: list[dict] = []
    RESULTS.mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="modelgen-cycle-") as tmp:
        for name in args.models:
            rows += run_model(name, Path(tmp), sf_python, args.symforce_max_states)
            (RESULTS / "cycle.json").write_text(json.dumps(rows, indent=2))  # after each model: a long run keeps what it measured
            text = markdown(rows)
            (RESULTS / "cycle.md").write_text(text)
            figure(rows, RESULTS / "cycle.png")
    print(text)
    print(f"written: {RESULTS / 'cycle.json'}, {RESULTS / 'cycle.md'}, {RESULTS / 'cycle.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
