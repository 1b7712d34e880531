"""Example-based blendshape generation: a template rig made personal from a few example expressions.

Alternates a basis step (deformation-gradient space, sparse least squares, eq. 2-4 of Gao et al.)
and a weight step (CasADi + IPOPT with bounds, a prior and complementarity ``x_a x_b = 0``, eq. 5),
each weight step certified globally optimal by branch and bound.

Modules
-------
generation     the problem, options, basis step and the alternating generator
weights        the eq. 5 weight step in CasADi, solved by IPOPT, polished by the certified solver
certify        exact box QPs and branch and bound over exclusive pairs (certified optima)
formulations   IPOPT formulations of complementarity compared against the certified optimum
examples       training inputs: example meshes, rough-weight files, exclusive pairs
runs           writing a generation run as a rig folder (weights, history, residuals, glTF)
verify         re-certify the stored weights of a run folder
crossval       automatic regularisation: k-fold cross-validation of alpha (``alpha="auto"``)
enrich         incremental enrichment: resume a finished run with more training expressions
synthetic      person problems with known answers built from the built-in face

May import :mod:`facebasis.contact` (the virtual-edge energy inside generation).

References
----------
Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015.
"""
