import time, sys, pickle
import sympy as sp
from modelgen.model.mechanizations import wander_azimuth as W
from modelgen.model.perturbation import change_of_variables as cv
orig = cv.declared_stage
def stage(problem, primitive):
    T, T_inv = cv._change_of_variables(problem)
    T_dot = cv._time_derivative(T, problem)
    mech = problem.mechanization()
    ms = [mech.at_operating_point(m) for m in (T, T_dot, T_inv, primitive.F, primitive.G, primitive.H)]
    import sympy
    sympy.srepr
    with open('/tmp/wander_factors.pkl','wb') as f: pickle.dump((ms, list(problem.state_order)), f)
    print("dumped", flush=True); sys.exit(0)
cv.declared_stage = stage
from modelgen.derivation.symbolic import derive
from modelgen.model.loading import load_model
import modelgen.model.perturbation.derivation as dd
for mod in list(sys.modules.values()):
    if getattr(mod, 'declared_stage', None) is orig: mod.declared_stage = stage
derive(load_model('tests/model/ins_gnss21_wander.yaml'))
