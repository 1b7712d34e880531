"""Grid-edge check of alpha="auto" (one-off; kept with its output grid_edge_m20_seed0.json).

``PYTHONPATH=. python problems/grid_edge.py 20 0`` (from the repository root): on the ICT
person problem (seed, m), cross-validation over the grid extended down to 1e-4, its choice and
held-out error, and the held-out error of the fixed schedule (5a, a) for every grid alpha.
"""
import json, time, os, sys
from facebasis.rigging.heldout import heldout_error
from facebasis.rigging.generation import BlendshapeGenerator
from facebasis.rigging.problem import GenerationOptions
from problems.generation import ict_person_problem
m=int(sys.argv[1]); seed=int(sys.argv[2])
grid=(1e-4,3e-4,1e-3,0.003,0.01,0.03,0.1,0.3,1.0,3.0,10.0,100.0)
pp=ict_person_problem(seed=seed,n_train=m); p=pp.problem
print("load", os.getloadavg(), flush=True)
t0,c0=time.perf_counter(),time.process_time()
res=BlendshapeGenerator(p,GenerationOptions(ipopt="never",alpha="auto",cv_grid=grid)).run()
w,c=time.perf_counter()-t0,time.process_time()-c0
cv=res.crossval
out={"m":m,"seed":seed,"grid":cv.grid,"errors":cv.errors,"best":cv.best_alpha,"heldout":heldout_error(res.rig,pp.heldout,p.pair_indices),"wall":w,"cpu":c,"load":os.getloadavg()}
# also held-out error of fixed schedules at each grid alpha
hs={}
for a in grid:
    r=BlendshapeGenerator(p,GenerationOptions(ipopt="never",alpha=(5*a,a))).run()
    hs[a]=heldout_error(r.rig,pp.heldout,p.pair_indices); print(a,hs[a],flush=True)
out["heldout_fixed"]=hs
print(json.dumps(out,indent=1))
json.dump(out, open(os.path.join(os.path.dirname(__file__), "..", "reports", "examples_study", f"grid_edge_m{m}_seed{seed}.json"), "w"), indent=1)
