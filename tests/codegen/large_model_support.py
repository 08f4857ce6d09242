"""Augmented models of any size: the 32-state augmented model plus sensor error states (for the large-model tests and bench).

``large_model(n)`` adds ``n - 32`` error states to ``ned_doppler32_augmented``,
alternating the two kinds an error budget adds most: a first-order
Gauss-Markov sensor error (``-e / tau + w``, its own driving noise: a diagonal
row of Phi) and a random constant (a unit row of Phi).  Each new state adds
its effect, times its own coefficient, to one of the velocity and attitude
errors (round robin), so the core rows of Phi fill across the new columns as
in a real augmented filter, and Q_d couples the core with the Markov states.
"""

from __future__ import annotations

from modelgen.model.declaration import ErrorModel, Noise, Parameter, State
from modelgen.model.loading import load_model
from modelgen.model.transform import augment

BASE = "ned_doppler32_augmented"
DRIVEN = ("alpha", "beta", "gamma", "dV_n", "dV_e")


def large_model(n_states: int) -> ErrorModel:
    """``ned_doppler32_augmented`` with ``n_states - 32`` added sensor error states (module docstring)."""
    base = load_model(BASE)
    extra = n_states - len(base.states)
    if extra < 1:
        raise ValueError(f"large_model: {n_states} states is not more than {BASE}'s {len(base.states)}")
    states, noises, parameters, equations = [], [], [], {}
    for k in range(extra):
        symbol = f"e_{k}"
        states.append(State(name=f"sensor_error_{k}", symbol=symbol, unit="1"))
        parameters.append(Parameter(name=f"coupling_{k}", symbol=f"c_e{k}", unit="1", value=1e-3 * (1 + k % 7)))
        if k % 2 == 0:
            parameters.append(Parameter(name=f"correlation_time_{k}", symbol=f"tau_{k}", unit="s", value=300.0 + 10 * k))
            noises.append(Noise(name=f"sensor_noise_{k}", symbol=f"w_e{k}", unit="1", psd=f"1e-10*{1 + k % 5}"))
            equations[symbol] = f"-{symbol}/tau_{k} + w_e{k}"
        else:
            equations[symbol] = "0"
        target = DRIVEN[k % len(DRIVEN)]
        term = f"c_e{k}*{symbol}"
        equations[target] = f"{equations[target]} + {term}" if target in equations else term
    return augment(
        base, states, equations, noises=noises, parameters=parameters, name=f"ned_doppler{n_states}_large",
        title=f"{BASE} with {extra} added sensor error states ({n_states} states)",
    )
