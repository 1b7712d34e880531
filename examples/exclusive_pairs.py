"""Exclusive pairs in the weight step (eq. 5): the certified optimum against two common shortcuts.

Two correlated shapes that may not be on together (x_0 x_1 = 0), solved three ways: the package's
branch and bound (certified global optimum), the production heuristic *cancel pairs* (solve without
the pair, zero the smaller weight, solve again) and IPOPT on the complementarity equality. The
closed form: the optimum keeps shape 1 (x = (0, 0.525), objective -1.1025); cancel-pairs keeps
shape 0 (objective -1). IPOPT finds the optimum on this small instance from its default start; on
ICT's 66-instance suite it does not always (see the example-based generation page), which is why
the certified solver gives every weight step's answer.
"""

import numpy as np

from _common import output_folder
from facebasis.report.figures import COLUMN, _pyplot, save
from facebasis.rigging.certify import certified_weights
from facebasis.rigging.formulations import FormulationSolver, cancel_pairs
from facebasis.rigging.weightproblem import WeightProblem

out = output_folder(__file__)
G = np.array([[1.0, 0.5], [0.5, 4.0]])        # Gram matrix B^T B of the two shapes
c = np.array([1.0, 2.1])                      # B^T (t - b0) of the expression
problem = WeightProblem(G, c, 0.0, [(0, 1)])
results = {"certified (B&B)": certified_weights(problem), "cancel pairs": cancel_pairs(problem),
           "IPOPT, x0 x1 = 0": FormulationSolver(2, [(0, 1)], "equality").solve_problem(problem)}
for name, r in results.items():
    print(f"{name:18s} x = {np.round(r.x, 4)}  objective {r.objective:.4f}  max |x0 x1| {r.max_complementarity:.1e}")

plt = _pyplot()
fig, ax = plt.subplots(figsize=(COLUMN, 2.4))
names = list(results)
ax.bar(range(len(names)), [results[n].objective for n in names], color=["tab:blue", "tab:orange", "tab:green"])
ax.set_xticks(range(len(names)), names)
ax.set_ylabel("eq. 5 objective (arbitrary units)")
ax.set_title("lower is better; B&B is the certified optimum")
save(fig, out / "objectives", ("png",))
print(f"figure: {out / 'objectives.png'}")
