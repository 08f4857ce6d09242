import pickle, time, sympy as sp, sys
(T, Td, Ti, F0, G0, H0), order = pickle.load(open('/tmp/wander_factors.pkl','rb'))
from modelgen.model.mechanizations import wander_azimuth as W
def plain(M):
    functions = list(M.atoms(sp.Derivative, *W.EARTH_FUNCTIONS))
    return functions
allf=set()
for M in (T,Td,Ti,F0,G0,H0): allf |= set(M.atoms(sp.Derivative, *W.EARTH_FUNCTIONS))
der=[a for a in allf if isinstance(a, sp.Derivative)]; app=[a for a in allf if not isinstance(a, sp.Derivative)]
st={a: sp.Dummy(f"e{k}") for k,a in enumerate(sorted(der,key=sp.default_sort_key)+sorted(app,key=sp.default_sort_key))}
def P(M): return M.xreplace({a:st[a] for a in der}).xreplace({a:st[a] for a in app}).xreplace({c:0 for c in W.CHART})
T,Td,Ti,F0,G0,H0=[P(M) for M in (T,Td,Ti,F0,G0,H0)]
t=time.process_time()
c=lambda M: M.applyfunc(lambda e: sp.cancel(e) if e!=0 else e)
Tc,Tdc,Tic=c(T),c(Td),c(Ti)
print("factor cancel", time.process_time()-t, flush=True)
A=(Tc*F0+Tdc)
print("A ops max", max(sp.count_ops(e) for e in A), flush=True)
Fp=A*Tic
times=[]
for i in range(Fp.rows):
  for j in range(Fp.cols):
    e=Fp[i,j]
    if e==0: continue
    t=time.process_time(); r=sp.cancel(e); dt=time.process_time()-t
    times.append((dt,i,j,sp.count_ops(e), sp.count_ops(r)))
    if dt>1: print(i,j,dt,flush=True)
times.sort(reverse=True); print("total", sum(x[0] for x in times)); print(times[:8])
