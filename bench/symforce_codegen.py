"""SymForce side of the benchmark; runs inside bench/.venv (SymForce is installed only there).

usage: python symforce_codegen.py SPEC.json OUT_DIR  -> prints JSON timings.
Generates C++ (Eigen) functions <name>_predict and <name>_update for the
structure in SPEC (see symbolic_kf.py).
"""

import json
import sys
import time
from pathlib import Path

import symforce

symforce.set_epsilon_to_number()

import symforce.symbolic as sf  # noqa: E402
from symforce import codegen  # noqa: E402
from symforce.values import Values  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from symbolic_kf import spec_matrices  # noqa: E402


def main() -> None:
    spec = json.loads(Path(sys.argv[1]).read_text())
    out = Path(sys.argv[2])
    n = spec["n"]
    timings = {}

    start = time.perf_counter()
    s = spec_matrices(spec, sf.Symbol, lambda r, c: sf.Matrix.zeros(r, c), sf.S(1))
    Phi, Qd, P, H = s["Phi"], s["Qd"], s["P"], s["H"]
    x = sf.Matrix(s["x"])
    Pn = Phi * P * Phi.T + Qd
    xn = Phi * x
    upper = sf.Matrix([Pn[i, j] for i in range(n) for j in range(i, n)])
    cg = codegen.Codegen(
        inputs=Values(phi=sf.Matrix(s["phi_in"]), p=sf.Matrix(s["p_in"]), qd=sf.Matrix(s["qd_in"]), x=x),
        outputs=Values(p_new=upper, x_new=xn),
        config=codegen.CppConfig(),
        name=f"{spec['name']}_predict",
        return_key=None,
    )
    cg.generate_function(output_dir=out, skip_directory_nesting=True)
    timings["predict"] = time.perf_counter() - start

    start = time.perf_counter()
    R = sf.Matrix.diag(s["r"])
    z = sf.Matrix(s["z"])
    S = H * P * H.T + R
    K = P * H.T * S.inv()
    x_up = x + K * (z - H * x)
    A = sf.Matrix.eye(n) - K * H
    P_up = A * P * A.T + K * R * K.T
    upper = sf.Matrix([P_up[i, j] for i in range(n) for j in range(i, n)])
    cg = codegen.Codegen(
        inputs=Values(p=sf.Matrix(s["p_in"]), h=sf.Matrix(s["h_in"]), r=sf.Matrix(s["r"]), x=x, z=z),
        outputs=Values(p_new=upper, x_new=x_up),
        config=codegen.CppConfig(),
        name=f"{spec['name']}_update",
        return_key=None,
    )
    cg.generate_function(output_dir=out, skip_directory_nesting=True)
    timings["update"] = time.perf_counter() - start
    print(json.dumps(timings))


if __name__ == "__main__":
    main()
