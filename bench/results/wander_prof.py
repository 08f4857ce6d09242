"""Where load + derive of modelgen/data/mechanizations/ins_gnss21_wander.yaml spends its time (issue 27 item 1).

Run: PYTHONPATH=. python bench/results/wander_prof.py [--profile]
Prints the CPU seconds (time.process_time) of the derivation's stages, then with --profile the
cProfile listing of modelgen's own functions (cumulative; cProfile roughly multiplies the times by 6-8).
"""

import cProfile
import functools
import pstats
import sys
import time

import modelgen.model.mechanizations.wander_azimuth as wander
import modelgen.model.navigation_model.derivation as navigation
import modelgen.model.perturbation.change_of_variables as change
import modelgen.model.perturbation.derivation as perturbation
import modelgen.model.perturbation.linearization as linearization
from modelgen.derivation.symbolic import derive
from modelgen.model.loading import load_model

MODEL = "modelgen/data/mechanizations/ins_gnss21_wander.yaml"
SECONDS: dict[str, float] = {}


def timed(owner, name, *also):
    """Replace owner.name (and the same function in the modules ``also``) by a version that adds up its CPU time."""
    original = getattr(owner, name)

    @functools.wraps(original)
    def run(*args, **kwargs):
        start = time.process_time()
        try:
            return original(*args, **kwargs)
        finally:
            SECONDS[name] = SECONDS.get(name, 0.0) + time.process_time() - start

    for module in (owner, *also):
        setattr(module, name, run)


timed(linearization, "primitive_stage", perturbation)
timed(linearization, "_measurement_jacobian")
timed(change, "declared_stage", perturbation)
timed(change, "_time_derivative")
timed(wander, "reduce_by_relations")
timed(wander.WanderAzimuth, "declared_products")
timed(perturbation, "finish")
timed(navigation, "_error_model")

start = time.process_time()
if "--profile" in sys.argv:
    cProfile.run(f"derive(load_model({MODEL!r}))", "/tmp/wander_prof.out")
else:
    derive(load_model(MODEL))
print(f"load + derive: {time.process_time() - start:.2f} s CPU")
for name, seconds in SECONDS.items():
    print(f"  {name}: {seconds:.2f} s")
if "--profile" in sys.argv:
    pstats.Stats("/tmp/wander_prof.out").sort_stats("cumulative").print_stats("modelgen", 25)
