"""SymForce side of the whole-cycle benchmark; runs inside bench/.venv (SymForce is installed only there).

usage: python symforce_cycle.py SPEC.json OUT_DIR  -> prints the code-generation seconds as JSON.

SPEC (written by bench_cycle.py) holds the model's F, G and diag(Q) as
expression text in the parameters p0, p1, ... (sympy syntax, printed by
modelgen from the derived model), the Taylor order and the sizes.  The one
generated C++ function takes (parameters, T, packed upper P, x) and returns
(packed upper P', x') with

    S = sum_{k<=N} (F T)^k / (k+1)! (by Horner's rule),  Phi = I + F T S,
    Gamma = T S G,  Q_d = Gamma diag(q / T) Gamma^T,  P' = Phi P Phi^T + Q_d,  x' = Phi x,

the paper's eqs. (9)-(11) as modelgen sums them (Phi = I + F T S is eq. (10)
to order N + 1, modelgen.derivation.discretization), exactly what CasADi is
given in bench_cycle.py.
SymForce runs with its default symengine back end; the expression text
(written by modelgen from its own derived model, not from a user) is read by
symengine's parser.
"""

import json
import math
import sys
import time
from pathlib import Path

import symforce

symforce.set_epsilon_to_number()

import symengine  # noqa: E402
import symforce.symbolic as sf  # noqa: E402
from symforce import codegen  # noqa: E402
from symforce.values import Values  # noqa: E402


def main() -> None:
    spec = json.loads(Path(sys.argv[1]).read_text())
    out = Path(sys.argv[2])
    n, nw, order = spec["n"], spec["nw"], spec["order"]
    start = time.perf_counter()
    params = [sf.Symbol(f"p{k}") for k in range(spec["n_params"])]
    names = {f"p{k}": s for k, s in enumerate(params)}

    def parse(text: str):
        return symengine.sympify(text).xreplace({symengine.Symbol(k): v for k, v in names.items()})

    T = sf.Symbol("T")
    F = sf.Matrix.zeros(n, n)
    for i, j, text in spec["F"]:
        F[i, j] = parse(text)
    G = sf.Matrix.zeros(n, max(nw, 1))
    for i, j, text in spec["G"]:
        G[i, j] = parse(text)
    q = [parse(text) for text in spec["q"]]
    packed = [sf.Symbol(f"P_{i}_{j}") for i in range(n) for j in range(i, n)]
    P = sf.Matrix.zeros(n, n)
    k = 0
    for i in range(n):
        for j in range(i, n):
            P[i, j] = packed[k]
            P[j, i] = packed[k]
            k += 1
    x = sf.Matrix([sf.Symbol(f"x_{i}") for i in range(n)])
    X = F * T
    S = sf.Matrix.eye(n) / math.factorial(order + 1)  # Horner: S = R_0, R_k = I / (k+1)! + X R_(k+1)
    for k in range(order - 1, -1, -1):
        S = X * S + sf.Matrix.eye(n) / math.factorial(k + 1)
    Phi = sf.Matrix.eye(n) + X * S
    Gamma = T * S * G
    Qd = Gamma * sf.Matrix.diag([qk / T for qk in q] or [0]) * Gamma.T
    Pn = Phi * P * Phi.T + Qd
    upper = sf.Matrix([Pn[i, j] for i in range(n) for j in range(i, n)])
    cg = codegen.Codegen(
        inputs=Values(params=sf.Matrix(params), T=T, p=sf.Matrix(packed), x=x),
        outputs=Values(p_new=upper, x_new=Phi * x),
        config=codegen.CppConfig(),
        name=f"{spec['name']}_cycle",
        return_key=None,
    )
    cg.generate_function(output_dir=out, skip_directory_nesting=True)
    print(json.dumps({"cycle": time.perf_counter() - start}))


if __name__ == "__main__":
    main()
