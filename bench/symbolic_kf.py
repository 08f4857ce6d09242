"""The filter equations written once for the symbolic code generators (benchmark only).

Both SymForce and CasADi get exactly the structure modelgen uses: Phi has
symbols only at its structural nonzeros (rows of random constants are e_i),
Q_d and H likewise, P is symmetric (one symbol per upper-triangle entry), R
is diagonal.  The functions return the upper triangle of the new P and the
new x.  ``ops`` is the tool's matrix module (it only needs zeros, products,
transpose, inverse); ``symbol`` makes one scalar symbol.
"""


def spec_matrices(spec, symbol, zeros, one):
    """Symbolic Phi, Qd, P (symmetric), x, H, r, z and the input vectors."""
    n, m = spec["n"], spec["m"]
    unit = set(spec["unit_rows"])
    phi_in, qd_in, p_in, h_in = [], [], [], []
    Phi = zeros(n, n)
    for i, j in spec["phi"]:
        s = symbol(f"phi_{i}_{j}")
        phi_in.append(s)
        Phi[i, j] = s
    for i in unit:
        Phi[i, i] = one
    Qd = zeros(n, n)
    for i, j in spec["qd"]:
        s = symbol(f"qd_{i}_{j}")
        qd_in.append(s)
        Qd[i, j] = s
        Qd[j, i] = s
    P = zeros(n, n)
    for i in range(n):
        for j in range(i, n):
            s = symbol(f"p_{i}_{j}")
            p_in.append(s)
            P[i, j] = s
            P[j, i] = s
    x = [symbol(f"x_{i}") for i in range(n)]
    H = zeros(m, n)
    for a, j in spec["h"]:
        s = symbol(f"h_{a}_{j}")
        h_in.append(s)
        H[a, j] = s
    r = [symbol(f"r_{a}") for a in range(m)]
    z = [symbol(f"z_{a}") for a in range(m)]
    return {"Phi": Phi, "Qd": Qd, "P": P, "x": x, "H": H, "r": r, "z": z,
            "phi_in": phi_in, "qd_in": qd_in, "p_in": p_in, "h_in": h_in}
