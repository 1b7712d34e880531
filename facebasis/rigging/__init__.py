"""Example-based blendshape generation: a template rig made personal from a few example expressions.

Alternates a basis step (deformation-gradient space, sparse least squares, eq. 2-4 of Gao et al.)
and a weight step (bounds, a prior and complementarity ``x_a x_b = 0``, eq. 5) solved to certified
global optima by branch and bound, with the CasADi + IPOPT model of eq. 5 as a recorded
cross-check.

Modules
-------
problem        the generation problem, its options and its result (one constructor,
               ``GenerationResult.from_weights``, which computes the residuals)
basis          the basis step (eq. 2-4), vectorised over triangles, and its array layouts
spdsolve       many small Cholesky solves (LAPACK ``dposv``) with the GIL released, for the basis step
generation     precompute once (``TemplatePart``, ``ExamplePart``), alternate the steps
               (``BlendshapeGenerator``, ``generate_blendshapes``)
weightproblem  the eq. 5 weight problem (``WeightProblem``: data in one layout, objective, residuals,
               pair checks) and its solutions (``WeightSolution``)
certify        the certified solve of a weight step (``certify_problem``: branch and bound over
               exclusive pairs, ``problem -> WeightSolution``; its nodes' box QPs by
               :mod:`facebasis.geometry.boxqp`)
weights        the IPOPT solve of a weight step (``WeightSolver.solve_problem``: the CasADi model
               of eq. 5, polished by ``certify_problem``; ``problem -> WeightSolution``)
formulations   IPOPT formulations of complementarity compared against the certified optimum
examples       training inputs: example meshes, rough-weight files, exclusive pairs
runs           writing a generation run as a rig folder (weights, history, residuals, glTF)
verify         re-certify the stored weights of a run folder
crossval       automatic regularisation: k-fold cross-validation of alpha (``alpha="auto"``,
               ``cross_validate_alpha``) and its procedures
cvcurve        the cross-validation curve (``CrossValidation``) and the procedures' settings
cvpath         the path procedures of ``alpha="auto"``: ``"coarse"`` (default) and ``"deletion"``
heldout        the one held-out error (``heldout_error``: certified refit, vertex residual) and the folds
enrich         incremental enrichment: resume a finished run with more training expressions
contactstep    exact contact on the generated shapes (``contact=True``, ``rig --contact``) and the
               final weight step solved again for them
synthetic      person problems with known answers built from the built-in face

Imports run one way inside the package (no cycle, function-local imports included):
generation -> crossval, contactstep -> certify -> weightproblem; the weight step's names are
imported from the module that defines them (nothing is re-exported).

May import :mod:`facebasis.contact` (the virtual-edge energy inside generation, exact contact in
``contactstep``).

References
----------
Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015.
"""
