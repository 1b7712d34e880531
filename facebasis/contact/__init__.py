"""Keeping thin facial layers apart: virtual edges, an exact intersection counter, exact contact.

Virtual edges join vertices that are close in space but far along the surface (lips, lids) and
are kept, softly, transformed like real edges during deformation transfer and generation. The
counter finds every intersecting triangle pair exactly (Shewchuk-style exact predicates) and
splits new pairs into local folds and layer crossings. Exact contact (``contact_transfer``,
``contact_correct``) corrects transferred or generated shapes so that no new pair intersects at all,
moving only vertices near the contacts.

Modules
-------
geodesics      bounded graph geodesics (Dijkstra on an unfolded edge graph), on all cores
virtual_edges  detection, thinning, targets and the energy's operator
penetration    exact triangle-pair intersection, new-pair reports, local folds vs layer crossings
proximity      fast conservative pair search (k-d trees of bounding balls), triangle-triangle distances
solver         exact contact for one shape: separating planes, the QP, the exact check after every solve
retreat        the last resort: a shape pulled back towards the target neutral around pairs left
qp             the separation QP: the transfer's normal matrix, the plane rows, ADMM (OSQP's splitting)
exact          exact contact for transferred and generated rigs (``contact_transfer``, ``contact_correct``),
               input checks, shapes in forked worker processes

References
----------
Li Hanchao, Shen Chengze, Liu Xinguo. Facial blendshape generation with virtual-edge constraints
    (带虚拟边约束的面部表情基生成算法). Chinese Journal of Computers, 2023(11).
"""
