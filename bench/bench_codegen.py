#!/usr/bin/env python
"""Benchmark: modelgen's generated C against dense C, numpy, SymForce and CasADi.

For the core paper's 18-state model and the 32-state augmented model
(``ned_doppler32_augmented``: scale factors and misalignments added), at the
same operating point and covariance for every implementation:

* instructions per covariance prediction and per measurement update, counted
  by valgrind's callgrind (deterministic, so repeatable on a busy machine);
* wall time per call (best of a few runs);
* memory: the storage each implementation needs beyond the model inputs
  (filter state, workspace, static temporaries) and the peak stack of one
  call (stack painting in bench/harness.c);
* code-generation wall time of each tool for both models (in-process after
  imports, as each tool is used from a script; for modelgen also the whole
  ``modelgen generate`` process, start-up and imports included).

Implementations: the generated C (default options, double); a
straightforward dense C filter (bench/dense_filter.c); numpy (the dense
reference, modelgen/derivation/reference.py; wall time only); the C++ that SymForce
generates and the C that CasADi generates from the same structured matrices
(bench/symbolic_kf.py: symbols only at structural nonzeros, symmetric P, so
both tools can exploit everything modelgen knows).  SymForce is installed
only in bench/.venv, which this script creates on first use; its C++ needs
Eigen (Debian libeigen3-dev, installed here if missing and running as root).

Targets (issue 6): generated prediction <= 1/2 the instructions of the dense
C and <= the best of SymForce and CasADi; generating both languages for the
18-state model in under 2 s.

usage: python bench/bench_codegen.py [--models ned_doppler18 ...] [--skip-symforce]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))  # runs from a fresh clone without installing

from modelgen.derivation import reference  # noqa: E402
from modelgen.codegen.generate import generate_code, write_atomically  # noqa: E402
from modelgen.codegen.structure import filter_structure  # noqa: E402
from modelgen.checks.code_check import measurement_sequence  # noqa: E402
from modelgen.derivation.symbolic import derive  # noqa: E402
from modelgen.derivation.discretization import taylor_discretization, taylor_process_noise  # noqa: E402
from modelgen.model.loading import load_model  # noqa: E402
from modelgen.jobs import paper_scenario, synthetic_scenario  # noqa: E402

MODELS = ("ned_doppler18", "ned_doppler32_augmented")
OPT = "-O2"
VENV = HERE / ".venv"
EIGEN = Path("/usr/include/eigen3")
CALLGRIND_CALLS = 20
START = time.perf_counter()


def progress(message: str) -> None:
    print(f"[{time.perf_counter() - START:7.1f} s] {message}", flush=True)


def run(command: list[str], **kw) -> subprocess.CompletedProcess:
    result = subprocess.run(command, capture_output=True, text=True, **kw)
    if result.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, command))} failed:\n{result.stdout[-2000:]}\n{result.stderr[-4000:]}")
    return result


# -- environments -----------------------------------------------------------------
def symforce_python() -> Path | None:
    """bench/.venv's python with SymForce, created on first use; None if that fails."""
    python = VENV / "bin" / "python"
    if python.exists() and subprocess.run([str(python), "-c", "import symforce"], capture_output=True).returncode == 0:
        return python
    progress("creating bench/.venv with SymForce (first run only, a few minutes) ...")
    try:
        run([sys.executable, "-m", "venv", str(VENV)])
        run([str(python), "-m", "pip", "install", "-q", "symforce", "numpy"])
    except RuntimeError as exc:
        progress(f"SymForce unavailable: {exc}")
        return None
    return python


def eigen_available() -> bool:
    if (EIGEN / "Eigen" / "Core").exists():
        return True
    if os.geteuid() == 0 and shutil.which("apt-get"):
        progress("installing Eigen headers (Debian libeigen3-dev) for SymForce's C++ ...")
        subprocess.run(["apt-get", "install", "-y", "-qq", "--no-install-recommends", "libeigen3-dev"], capture_output=True,
                       env={**os.environ, "DEBIAN_FRONTEND": "noninteractive"})
    return (EIGEN / "Eigen" / "Core").exists()


# -- the problem ------------------------------------------------------------------
def problem(name: str) -> dict:
    """Derived model, structure, numeric matrices and a realistic P for ``name``."""
    derived = derive(load_model(name))
    scenario = paper_scenario(derived) if name == "ned_doppler18" else synthetic_scenario(derived)
    m = derived.numeric(scenario.parameters)
    phi, gamma = taylor_discretization(m["F"], m["G"], scenario.step, 9)
    qd = taylor_process_noise(gamma, m["Q"], scenario.step)
    x, P = scenario.x0(), scenario.initial_covariance.copy()
    zs = measurement_sequence(derived, scenario)
    for z in zs[:10]:  # a covariance with the filter's real correlations
        x = phi @ x
        P = reference.predict_covariance(P, phi, qd)
        x, P = reference.update(x, P, z, m["H"], m["R"])
    structure = filter_structure(derived.structure("F"), derived.structure("G"), derived.structure("H"), 9)
    return {"name": name, "derived": derived, "structure": structure, "Phi": phi, "Qd": qd, "P": P, "x": x,
            "H": m["H"], "r": np.diag(m["R"]).copy(), "z": zs[10], "n": derived.n_states, "m": derived.n_measurements}


def spec(p: dict) -> dict:
    s = p["structure"]
    unit = set(s.unit_rows)
    return {
        "name": f"kf{p['n']}",
        "n": p["n"],
        "m": p["m"],
        "phi": [(i, j) for i, j in s.entries("Phi") if i not in unit],
        "unit_rows": sorted(unit),
        "qd": [(i, j) for i, j in s.entries("Qd") if i <= j],
        "h": s.entries("H"),
    }


def input_file(p: dict, folder: Path) -> Path:
    path = folder / "input.bin"
    path.write_bytes(b"".join(np.ascontiguousarray(a, dtype=np.float64).tobytes() for a in (p["Phi"], p["Qd"], p["P"], p["x"], p["H"], p["r"], p["z"])))
    return path


# -- glue per implementation -----------------------------------------------------------
def glue_generated(model: str) -> str:
    return f"""#include "{model}.h"
static {model}_transition tr;
static {model}_filter filt, saved;
static {model}_workspace ws;
static {model}_matrices mat;
static void setup(void)
{{
    int e, a, i, j;
    for (e = 0; e < {model.upper()}_N_PHI; ++e) tr.Phi[e] = in_Phi[{model}_Phi_row[e]][{model}_Phi_col[e]]; /* Phi compressed to its pattern */
    for (i = 0, e = 0; i < BENCH_N; ++i) {{
        for (j = i; j < BENCH_N; ++j) tr.Qd[e++] = in_Qd[i][j]; /* the transition keeps Q_d packed (upper) */
    }}
    memcpy(filt.x, in_x, sizeof in_x);
    memcpy(filt.P, in_P, sizeof in_P);
    for (e = 0; e < {model.upper()}_NNZ_H; ++e) mat.H[e] = in_H[{model}_H_row[e]][{model}_H_col[e]];
    for (a = 0; a < BENCH_M; ++a) mat.r[a] = in_r[a];
    saved = filt;
}}
static void restore(void) {{ filt = saved; }}
__attribute__((noinline)) void bench_predict_once(void) {{ if ({model}_predict(&filt, &tr, &ws)) abort(); }}
__attribute__((noinline)) void bench_update_once(void) {{ if ({model}_update(&filt, in_z, &mat, &ws)) abort(); }}
static double checksum(void) {{ return filt.P[0][0] + filt.x[0]; }}
static unsigned long storage_bytes(void) {{ return (unsigned long)(sizeof filt + sizeof ws); }}
"""


GLUE_DENSE = """#define N BENCH_N
#define M BENCH_M
#include "dense_filter.h"
static double x[N], P[N][N];
static void setup(void) { }
static void restore(void) { memcpy(x, in_x, sizeof x); memcpy(P, in_P, sizeof P); }
__attribute__((noinline)) void bench_predict_once(void) { dense_predict(x, P, (const double (*)[N])in_Phi, (const double (*)[N])in_Qd); }
__attribute__((noinline)) void bench_update_once(void) { if (dense_update(x, P, in_z, (const double (*)[N])in_H, in_r)) abort(); }
static double checksum(void) { return P[0][0] + x[0]; }
static unsigned long storage_bytes(void) { return (unsigned long)(sizeof x + sizeof P) + dense_scratch_bytes(); }
"""


def pack_inputs_c(sp: dict, array: str, kind: str) -> str:
    """C statements filling a flat input vector from the in_* arrays, in symbol order."""
    if kind == "phi":
        return "\n".join(f"    {array}[{k}] = in_Phi[{i}][{j}];" for k, (i, j) in enumerate(sp["phi"]))
    if kind == "qd":
        return "\n".join(f"    {array}[{k}] = in_Qd[{i}][{j}];" for k, (i, j) in enumerate(sp["qd"]))
    if kind == "h":
        return "\n".join(f"    {array}[{k}] = in_H[{a}][{j}];" for k, (a, j) in enumerate(sp["h"]))
    if kind == "p":
        n = sp["n"]
        pairs = [(i, j) for i in range(n) for j in range(i, n)]
        return "\n".join(f"    {array}[{k}] = in_P[{i}][{j}];" for k, (i, j) in enumerate(pairs))
    raise ValueError(kind)


def glue_casadi(sp: dict, sizes: dict) -> str:
    n = sp["n"]
    npk = n * (n + 1) // 2
    name = sp["name"]
    return f"""#include "casadi_{name}.h"
static casadi_real phi_v[{max(len(sp['phi']), 1)}], qd_v[{max(len(sp['qd']), 1)}], p_v[{npk}], x_v[BENCH_N], h_v[{max(len(sp['h']), 1)}];
static casadi_real pn_v[{npk}], xn_v[BENCH_N];
static casadi_int iw[{sizes['iw'] + 1}];
static casadi_real w[{sizes['w'] + 1}];
static const casadi_real *arg_p[{sizes['arg'] + 1}], *arg_u[{sizes['arg'] + 1}];
static casadi_real *res[{sizes['res'] + 1}];
static void setup(void)
{{
{pack_inputs_c(sp, 'phi_v', 'phi')}
{pack_inputs_c(sp, 'qd_v', 'qd')}
{pack_inputs_c(sp, 'p_v', 'p')}
{pack_inputs_c(sp, 'h_v', 'h')}
    memcpy(x_v, in_x, sizeof x_v);
    arg_p[0] = phi_v; arg_p[1] = p_v; arg_p[2] = qd_v; arg_p[3] = x_v;
    arg_u[0] = p_v; arg_u[1] = h_v; arg_u[2] = in_r; arg_u[3] = x_v; arg_u[4] = in_z;
    res[0] = pn_v; res[1] = xn_v;
}}
static void restore(void) {{ }}
__attribute__((noinline)) void bench_predict_once(void) {{ {name}_predict(arg_p, res, iw, w, 0); }}
__attribute__((noinline)) void bench_update_once(void) {{ {name}_update(arg_u, res, iw, w, 0); }}
static double checksum(void) {{ return pn_v[0] + xn_v[0]; }}
static unsigned long storage_bytes(void) {{ return (unsigned long)(sizeof p_v + sizeof x_v + sizeof pn_v + sizeof xn_v + sizeof iw + sizeof w); }}
"""


def glue_symforce(sp: dict) -> str:
    n = sp["n"]
    npk = n * (n + 1) // 2
    name = sp["name"]
    camel = "".join(part.capitalize() for part in name.split("_"))
    return f"""#include <Eigen/Core>
#include "{name}_predict.h"
#include "{name}_update.h"
static Eigen::Matrix<double, {len(sp['phi'])}, 1> phi_v;
static Eigen::Matrix<double, {len(sp['qd'])}, 1> qd_v;
static Eigen::Matrix<double, {npk}, 1> p_v, pn_v;
static Eigen::Matrix<double, BENCH_N, 1> x_v, xn_v;
static Eigen::Matrix<double, {len(sp['h'])}, 1> h_v;
static Eigen::Matrix<double, BENCH_M, 1> r_v, z_v;
static void setup(void)
{{
{pack_inputs_c(sp, 'phi_v', 'phi')}
{pack_inputs_c(sp, 'qd_v', 'qd')}
{pack_inputs_c(sp, 'p_v', 'p')}
{pack_inputs_c(sp, 'h_v', 'h')}
    for (int i = 0; i < BENCH_N; ++i) x_v[i] = in_x[i];
    for (int a = 0; a < BENCH_M; ++a) {{ r_v[a] = in_r[a]; z_v[a] = in_z[a]; }}
}}
static void restore(void) {{ }}
extern "C" __attribute__((noinline)) void bench_predict_once(void) {{ sym::{camel}Predict<double>(phi_v, p_v, qd_v, x_v, &pn_v, &xn_v); }}
extern "C" __attribute__((noinline)) void bench_update_once(void) {{ sym::{camel}Update<double>(p_v, h_v, r_v, x_v, z_v, &pn_v, &xn_v); }}
static double checksum(void) {{ return pn_v[0] + xn_v[0]; }}
static unsigned long storage_bytes(void) {{ return (unsigned long)(sizeof p_v + sizeof x_v + sizeof pn_v + sizeof xn_v); }}
"""


def build_harness(folder: Path, glue: str, sources: list[Path], p: dict, cxx: bool = False, includes: tuple[Path, ...] = (),
                  libraries: tuple[Path, ...] = ()) -> Path:
    """The harness with ``glue``, the ``sources`` compiled at OPT and prebuilt ``libraries`` (archives) linked in."""
    (folder / "glue.h").write_text(glue)
    exe = folder / "harness"
    incs = ["-I", str(folder), "-I", str(HERE), *[f"-I{i}" for i in includes]]
    objects = []
    for k, source in enumerate(sources):  # each source on its own, without the harness's macros
        obj = folder / f"part{k}.o"
        defines = [f"-DN={p['n']}", f"-DM={p['m']}"] if source.name == "dense_filter.c" else []
        run(["gcc", "-std=gnu99", OPT, *defines, *incs, "-c", str(source), "-o", str(obj)])
        objects.append(str(obj))
    objects += map(str, libraries)
    flags = [OPT, f"-DBENCH_N={p['n']}", f"-DBENCH_M={p['m']}", '-DBENCH_GLUE="glue.h"', *incs]
    if cxx:
        command = ["g++", "-std=c++14", "-DNDEBUG", *flags, "-x", "c++", str(HERE / "harness.c"), "-x", "none", *objects, "-o", str(exe), "-lm"]
    else:
        command = ["gcc", "-std=gnu99", *flags, str(HERE / "harness.c"), *objects, "-o", str(exe), "-lm"]
    run(command)
    return exe


def callgrind_instructions(exe: Path, data: Path, what: str) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        run(["valgrind", "--tool=callgrind", f"--toggle-collect=bench_{what}_once", f"--callgrind-out-file={out}",
             str(exe), str(data), "callgrind", what, str(CALLGRIND_CALLS)])
        text = out.read_text()
    match = re.search(r"^(?:totals|summary):\s*(\d+)", text, re.M)
    return int(match.group(1)) / CALLGRIND_CALLS


def wall_ns(exe: Path, data: Path, what: str) -> float:
    iterations = 20000 if what == "predict" else 20000
    best = min(float(run([str(exe), str(data), "time", what, str(iterations)]).stdout.split()[0]) for _ in range(3))
    return best


def memory_bytes(exe: Path, data: Path, what: str) -> tuple[int, int]:
    """(peak stack of one call, storage) as the harness measures them (bench/harness.c)."""
    stack, storage = run([str(exe), str(data), "memory", what, "1"]).stdout.split()[:2]
    return int(stack), int(storage)


def numpy_wall_ns(p: dict, what: str) -> float:
    Phi, Qd, P, x, H, R, z = p["Phi"], p["Qd"], p["P"], p["x"], p["H"], np.diag(p["r"]), p["z"]
    if what == "predict":
        def call():
            return Phi @ x, reference.predict_covariance(P, Phi, Qd)
    else:
        def call():
            return reference.update(x, P, z, H, R)
    best = float("inf")
    for _ in range(3):
        start = time.perf_counter()
        for _ in range(2000):
            call()
        best = min(best, (time.perf_counter() - start) / 2000 * 1e9)
    return best


# -- code generation by each tool ----------------------------------------------------
def modelgen_codegen(name: str, folder: Path) -> tuple[float, float, Path]:
    """(derive + generate both languages, generate only) seconds; writes the code."""
    start = time.perf_counter()
    derived = derive(load_model(name))
    middle = time.perf_counter()
    code = generate_code(derived)
    end = time.perf_counter()
    write_atomically(folder, code.files)
    return end - start, end - middle, folder


def casadi_codegen(sp: dict, folder: Path) -> tuple[float, dict]:
    import casadi as ca

    from symbolic_kf import spec_matrices

    start = time.perf_counter()
    n = sp["n"]
    s = spec_matrices(sp, ca.SX.sym, lambda r, c: ca.SX(r, c), 1)
    Phi, Qd, P, H = s["Phi"], s["Qd"], s["P"], s["H"]
    x, r, z = ca.vertcat(*s["x"]), ca.vertcat(*s["r"]), ca.vertcat(*s["z"])
    upper = lambda A: ca.vertcat(*[A[i, j] for i in range(n) for j in range(i, n)])  # noqa: E731
    Pn = ca.mtimes([Phi, P, Phi.T]) + Qd
    outs = [upper(Pn), ca.mtimes(Phi, x)]
    if hasattr(ca, "cse"):
        outs = [ca.cse(o) for o in outs]
    predict = ca.Function(f"{sp['name']}_predict", [ca.vertcat(*s["phi_in"]), ca.vertcat(*s["p_in"]), ca.vertcat(*s["qd_in"]), x], outs)
    R = ca.diag(r)
    S = ca.mtimes([H, P, H.T]) + R
    K = ca.mtimes([P, H.T, ca.inv(S)])
    A = ca.SX.eye(n) - ca.mtimes(K, H)
    Pu = ca.mtimes([A, P, A.T]) + ca.mtimes([K, R, K.T])
    outs = [upper(Pu), x + ca.mtimes(K, z - ca.mtimes(H, x))]
    if hasattr(ca, "cse"):
        outs = [ca.cse(o) for o in outs]
    update = ca.Function(f"{sp['name']}_update", [ca.vertcat(*s["p_in"]), ca.vertcat(*s["h_in"]), r, x, z], outs)
    cg = ca.CodeGenerator(f"casadi_{sp['name']}.c", {"with_header": True})
    cg.add(predict)
    cg.add(update)
    cg.generate(str(folder) + "/")
    seconds = time.perf_counter() - start
    sizes = {k: max(getattr(predict, f"sz_{k}")(), getattr(update, f"sz_{k}")()) for k in ("arg", "res", "iw", "w")}
    return seconds, sizes


def symforce_codegen(python: Path, sp: dict, folder: Path) -> float:
    spec_path = folder / "spec.json"
    spec_path.write_text(json.dumps(sp))
    start = time.perf_counter()
    out = run([str(python), str(HERE / "symforce_codegen.py"), str(spec_path), str(folder)], timeout=3600)
    wall = time.perf_counter() - start
    inner = json.loads(out.stdout.strip().splitlines()[-1])
    return inner["predict"] + inner["update"], wall


# -- main ----------------------------------------------------------------------------
def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--models", nargs="+", default=list(MODELS))
    parser.add_argument("--skip-symforce", action="store_true")
    args = parser.parse_args()
    for tool in ("gcc", "valgrind"):
        if shutil.which(tool) is None:
            print(f"{tool} is required (Debian: apt-get install {tool})")
            return 2
    sf_python = None if args.skip_symforce else symforce_python()
    if sf_python is not None and shutil.which("g++") is None:
        progress("g++ missing: SymForce's C++ cannot be built; skipping SymForce")
        sf_python = None
    if sf_python is not None and not eigen_available():
        progress("Eigen headers missing (apt-get install libeigen3-dev): skipping SymForce")
        sf_python = None

    results = {}
    with tempfile.TemporaryDirectory(prefix="modelgen-bench-") as tmp:
        root = Path(tmp)
        for name in args.models:
            progress(f"{name}: deriving and setting up the problem")
            p = problem(name)
            sp = spec(p)
            work = root / name
            work.mkdir()
            data = input_file(p, work)
            res = {"n": p["n"], "m": p["m"], "codegen": {}, "instructions": {}, "wall_ns": {}, "stack_bytes": {},
                   "storage_bytes": {}}

            progress(f"{name}: modelgen code generation (derive + Python and C)")
            total, gen_only, gen_folder = modelgen_codegen(name, work / "modelgen")
            res["codegen"]["modelgen"] = total
            res["codegen"]["modelgen (generate only)"] = gen_only
            start = time.perf_counter()
            run([sys.executable, "-m", "modelgen.cli", "generate", name, "--out", str(work / "cli")], cwd=REPO)
            res["codegen"]["modelgen CLI process"] = time.perf_counter() - start
            progress(f"{name}: CasADi code generation")
            (work / "casadi").mkdir()
            sys.path.insert(0, str(HERE))
            res["codegen"]["casadi"], casadi_sizes = casadi_codegen(sp, work / "casadi")
            if sf_python is not None:
                progress(f"{name}: SymForce code generation (in bench/.venv)")
                (work / "symforce").mkdir()
                res["codegen"]["symforce"], res["codegen"]["symforce (incl. start-up)"] = symforce_codegen(sf_python, sp, work / "symforce")

            builds = {}
            progress(f"{name}: compiling the harnesses ({OPT})")
            for impl in ("generated", "dense", "casadi", "symforce"):
                folder = work / f"build-{impl}"
                folder.mkdir()
                if impl == "generated":
                    builds[impl] = build_harness(folder, glue_generated(name), [gen_folder / f"{name}.c"], p, includes=(gen_folder,))
                elif impl == "dense":
                    builds[impl] = build_harness(folder, GLUE_DENSE, [HERE / "dense_filter.c"], p)
                elif impl == "casadi":
                    builds[impl] = build_harness(folder, glue_casadi(sp, casadi_sizes), [work / "casadi" / f"casadi_{sp['name']}.c"], p, includes=(work / "casadi",))
                elif sf_python is not None:
                    builds[impl] = build_harness(folder, glue_symforce(sp), [], p, cxx=True, includes=(work / "symforce", EIGEN))
            for impl, exe in builds.items():
                for what in ("predict", "update"):
                    progress(f"{name}: callgrind {impl} {what}")
                    res["instructions"][f"{impl} {what}"] = callgrind_instructions(exe, data, what)
                    res["wall_ns"][f"{impl} {what}"] = wall_ns(exe, data, what)
                    res["stack_bytes"][f"{impl} {what}"], res["storage_bytes"][impl] = memory_bytes(exe, data, what)
            for what in ("predict", "update"):
                res["wall_ns"][f"numpy {what}"] = numpy_wall_ns(p, what)
            results[name] = res
            report(name, res)

    print()
    print("=" * 78)
    summary(results)
    out = HERE / "results_codegen.json"
    out.write_text(json.dumps(results, indent=2, sort_keys=True))
    print(f"\nraw numbers: {out}")
    return 0


def report(name: str, res: dict) -> None:
    print(f"\n{name} ({res['n']} states, {res['m']} measurements)")
    print(f"  {'implementation':<12} {'predict Ir':>12} {'update Ir':>12} {'predict ns':>12} {'update ns':>12}")
    for impl in ("generated", "dense", "symforce", "casadi", "numpy"):
        ins = [res["instructions"].get(f"{impl} {w}") for w in ("predict", "update")]
        ns = [res["wall_ns"].get(f"{impl} {w}") for w in ("predict", "update")]
        if all(v is None for v in ins + ns):
            continue
        cells = [f"{v:12.0f}" if v is not None else f"{'-':>12}" for v in ins + ns]
        print(f"  {impl:<12} " + " ".join(cells))
    print(f"  {'memory [B]':<12} {'storage':>12} {'stack pred.':>12} {'stack upd.':>12}")
    for impl, static in res["storage_bytes"].items():
        stacks = [res["stack_bytes"][f"{impl} {w}"] for w in ("predict", "update")]
        print(f"  {impl:<12} {static:12d} {stacks[0]:12d} {stacks[1]:12d}")
    print("  code generation [s]: " + ", ".join(f"{k} {v:.2f}" for k, v in res["codegen"].items()))


def summary(results: dict) -> None:
    print("ratios (generated / other; < 1 means the generated code is cheaper)")
    for name, res in results.items():
        ins, ns = res["instructions"], res["wall_ns"]
        for what in ("predict", "update"):
            g = ins[f"generated {what}"]
            parts = [f"{other} {g / ins[f'{other} {what}']:.3f}" for other in ("dense", "symforce", "casadi") if f"{other} {what}" in ins]
            parts_ns = [f"{other} {ns[f'generated {what}'] / ns[f'{other} {what}']:.3f}" for other in ("dense", "symforce", "casadi", "numpy") if f"{other} {what}" in ns]
            print(f"  {name} {what}: instructions vs " + ", ".join(parts) + "; wall time vs " + ", ".join(parts_ns))
        memory = {impl: static + max(res["stack_bytes"][f"{impl} {w}"] for w in ("predict", "update"))
                  for impl, static in res["storage_bytes"].items()}
        parts = [f"{other} {memory['generated'] / memory[other]:.3f}" for other in ("dense", "symforce", "casadi") if other in memory]
        print(f"  {name} memory (storage + peak stack): " + ", ".join(parts))
    print("targets")
    for name, res in results.items():
        ins = res["instructions"]
        g = ins["generated predict"]
        dense = ins["dense predict"]
        best_tool = min([ins[k] for k in ("symforce predict", "casadi predict") if k in ins], default=None)
        verdict = "met" if g <= 0.5 * dense else "MISSED"
        print(f"  {name}: generated prediction {g:.0f} Ir <= 1/2 dense ({0.5 * dense:.0f}): {verdict}")
        if best_tool is not None:
            verdict = "met" if g <= best_tool else "MISSED"
            print(f"  {name}: generated prediction {g:.0f} Ir <= best of SymForce/CasADi ({best_tool:.0f}): {verdict}")
    if "ned_doppler18" in results:
        t = results["ned_doppler18"]["codegen"]["modelgen"]
        print(f"  ned_doppler18: derive + generate Python and C in {t:.2f} s < 2 s: {'met' if t < 2 else 'MISSED'}")


if __name__ == "__main__":
    sys.exit(main())
