"""Example-based blendshape generation: a template rig made personal from a few example expressions.

Alternates a basis step (deformation-gradient space, sparse least squares, eq. 2-4 of Gao et al.)
and a weight step (bounds, a prior and complementarity ``x_a x_b = 0``, eq. 5) solved to certified
global optima by branch and bound, with the CasADi + IPOPT model of eq. 5 as a recorded
cross-check.

Modules
-------
problem        the generation problem, its options and its result
basis          the basis step (eq. 2-4), vectorised over triangles, and its array layouts
spdsolve       many small Cholesky solves (LAPACK ``dposv``) with the GIL released, for the basis step
generation     precompute once, alternate the steps (``BlendshapeGenerator``, ``generate_blendshapes``)
weightproblem  the eq. 5 weight problem (``WeightProblem``: data, objective, residuals, pair checks)
               and its solutions (``WeightSolution``)
weights        the eq. 5 weight step: the certified solver and the CasADi/IPOPT model
certify        branch and bound over exclusive pairs (certified optima of a ``WeightProblem``)
boxqp          exact convex box-constrained QPs (DAQP + active-set refinement), the tree's nodes
formulations   IPOPT formulations of complementarity compared against the certified optimum
examples       training inputs: example meshes, rough-weight files, exclusive pairs
runs           writing a generation run as a rig folder (weights, history, residuals, glTF)
verify         re-certify the stored weights of a run folder
crossval       automatic regularisation: k-fold cross-validation of alpha (``alpha="auto"``)
enrich         incremental enrichment: resume a finished run with more training expressions
contactstep    exact contact on the generated shapes (``contact=True``, ``rig --contact``) and the
               final weight step solved again for them
synthetic      person problems with known answers built from the built-in face

May import :mod:`facebasis.contact` (the virtual-edge energy inside generation, exact contact in
``contactstep``).

References
----------
Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015.
"""
