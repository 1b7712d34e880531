"""Deformation transfer of a blendshape rig onto a new neutral (Sumner & Popovic 2004).

For template shape i the per-triangle deformation gradient is ``Q_i = A_i^S (A_0^S)^-1``
(Sumner & Popovic eq. 4; Gao et al. 2015, eq. 3 writes the transferred target frame as
``A~_i = Q_i A_0^B``). The target shape is the mesh whose triangle edges best match the
transferred edges ``Q_i e^B`` in least squares, with the translation fixed at anchor vertices:

    min_d  sum_t sum_e || (E d)_{t,e} - (Q_{i,t} - I) e^B_{t,e} ||^2,   d = B_i - B_0,
    d[a] = S_i[a] - S_0[a]  at the anchors a (still vertices of the template).

Solving for the delta ``d`` rather than the positions keeps still regions exactly still.

References
----------
- Sumner R. W., Popovic J. Deformation transfer for triangle meshes. ACM Transactions on Graphics
    23(3) (SIGGRAPH 2004): 399-405.
- Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015. Equation numbers
    "eq. N" in this module are this paper's unless another paper is named.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .gradients import frames_cm, triangle_frames
from .mesh import validate_mesh, validate_vertices
from .poisson import EdgePoisson, choose_anchors
from .rig import Rig


#: shapes transferred per solve in :meth:`DeformationTransfer.transfer` (without virtual edges). Each
#: shape has its own columns in the solve, so grouping changes at most the rounding (and groups of
#: 8 keep every column's position modulo 24, which gave bitwise the single solve's result on the
#: 14k-vertex ICT rig). Groups of 8 keep the (k, 3, 3, m) temporaries under 32 MB, which the
#: allocator then reuses instead of mapping fresh pages: on a 14k-vertex rig, first touches of
#: fresh pages (up to 0.7 s of system time for 53 shapes at once) cost more than the arithmetic.
SHAPES_PER_SOLVE = 8


def template_motion(rig: Rig) -> np.ndarray:
    """Largest displacement of every vertex over all shapes, (n,); the squares are formed for a
    group of shapes at a time (the same values, without a (k, n, 3) temporary)."""
    step = SHAPES_PER_SOLVE
    sq = (rig.deltas[:step] ** 2).sum(-1).max(0)
    for s in range(step, rig.n_shapes, step):
        np.maximum(sq, (rig.deltas[s:s + step] ** 2).sum(-1).max(0), out=sq)
    return np.sqrt(sq)


def rig_anchors(rig: Rig) -> np.ndarray:
    """Default anchors for a rig: its still vertices, plus one per component with none."""
    scale = float(np.linalg.norm(np.ptp(rig.neutral, axis=0)))
    return choose_anchors(rig.faces, rig.n_vertices, template_motion(rig), scale=scale)


class DeformationTransfer:
    """Stateful deformation transfer: precomputes frames and factors the solve once.

    Parameters
    ----------
    template : Rig, the source rig ``S_0, S_1..S_k``
    target_neutral : (n, 3) the target's neutral ``B_0`` in the template's topology
    anchors : optional (a,) anchor vertices (default :func:`rig_anchors`)
    extra_operator, extra_weight : optional extra least-squares rows (sparse (r, n) operator and
        its weight) for :class:`EdgePoisson`; their targets go to :meth:`solve_frame_deltas`
    virtual_edges : optional extra edge term, e.g. :class:`facebasis.contact.virtual_edges.VirtualEdges`
        (Li, Shen, Liu 2023): adds ``virtual_weight * sum ||(x_v - x_u) - t_i||^2`` to the solve.
        Geometry does not import the contact method; it uses the object's interface: ``n_vertices``,
        ``len()``, ``source``, ``operator()`` (sparse (e, n)), ``default_weight``, ``modes`` and
        ``targets(template_neutral, deltas, target_neutral, F, mode, neutral_frames, frame_deltas)``
        -> (k, e, 3)
    virtual_weight : its weight (default: the term's ``default_weight``, 1 for virtual edges)
    virtual_mode : ``"proportional"`` (default) or ``"gradient"`` targets (:func:`~facebasis.contact.virtual_edges.virtual_edge_targets`)

    Examples
    --------
    >>> from facebasis.defaults.face import default_person, default_template
    >>> template = default_template()
    >>> dt = DeformationTransfer(template, default_person().neutral)  # frames + one factorisation
    >>> target_rig = dt.transfer()                                     # all shapes at once
    >>> target_rig.deltas.shape == (template.n_shapes, template.n_vertices, 3)
    True
    """

    def __init__(self, template: Rig, target_neutral: np.ndarray, anchors=None,
                 extra_operator=None, extra_weight: float = 0.0, virtual_edges=None,
                 virtual_weight: float | None = None, virtual_mode: str = "proportional"):
        B0 = validate_vertices(target_neutral, "target neutral", template.n_vertices)
        validate_mesh(B0, template.faces, "target neutral")
        self.template = template
        self.target_neutral = B0
        F = template.faces
        self.template_frames = frames_cm(template.neutral, F)  # A_0^S, (3, 3, m)
        A0_inv = np.linalg.inv(np.moveaxis(self.template_frames, -1, 0))  # (m, 3, 3)
        self.target_frames = frames_cm(B0, F)  # A_0^B, (3, 3, m)
        # M_t = (A_0^S)^-1 A_0^B[:, :2], so that Q_i A_0^B[:, :2] - A_0^B[:, :2] = (A_i^S - A_0^S) M
        self._M = np.ascontiguousarray(np.moveaxis(A0_inv @ np.moveaxis(self.target_frames[:, :2], -1, 0), 0, -1))
        self.anchors = rig_anchors(template) if anchors is None else np.asarray(anchors, dtype=np.int64)
        self.virtual_edges = virtual_edges
        self.virtual_mode = virtual_mode
        if virtual_edges is not None:
            if virtual_mode not in virtual_edges.modes:
                raise InputError(f"virtual edge mode: expected one of {virtual_edges.modes}, found {virtual_mode!r}")
            if extra_operator is not None:
                raise InputError("DeformationTransfer: expected either virtual_edges or extra_operator, found both")
            if virtual_edges.n_vertices != template.n_vertices:
                raise InputError(f"virtual edges ({virtual_edges.source}): expected a mesh of {template.n_vertices} "
                                 f"vertices, found edges for {virtual_edges.n_vertices}")
            extra_weight = virtual_edges.default_weight if virtual_weight is None else float(virtual_weight)
            if not (extra_weight > 0 and np.isfinite(extra_weight)):
                raise InputError(f"virtual edge weight: expected a positive number, found {extra_weight}")
            extra_operator = virtual_edges.operator() if len(virtual_edges) else None
        self.virtual_weight = extra_weight
        self.poisson = EdgePoisson(F, template.n_vertices, self.anchors,
                                   extra_operator=extra_operator, extra_weight=extra_weight)

    def gradients(self, deltas: np.ndarray | None = None) -> np.ndarray:
        """Deformation gradients ``Q_i = A_i^S (A_0^S)^-1`` of the template shapes, (k, m, 3, 3)."""
        D = self.template.deltas if deltas is None else deltas
        A0_inv = np.linalg.inv(np.moveaxis(self.template_frames, -1, 0))
        return triangle_frames(self.template.neutral + D, self.template.faces) @ A0_inv

    def transferred_frame_deltas(self, deltas: np.ndarray | None = None, frame_deltas=None) -> np.ndarray:
        """Seed 000 eq. 3: ``A~_i = Q_i A_0^B - A_0^B``, edge columns only, (k, 3, 2, m).

        Computed as ``(A_i^S - A_0^S) M`` with ``M = (A_0^S)^-1 A_0^B[:, :2]`` precomputed, which
        is the same quantity without forming ``Q``.
        """
        if frame_deltas is None:
            D = self.template.deltas if deltas is None else deltas
            dA = frames_cm(self.template.neutral + D, self.template.faces)  # (k, 3, 3, m)
            dA -= self.template_frames
        else:  # precomputed A_i^S - A_0^S, (k, 3, 3, m)
            dA = frame_deltas
        # out[k, x, j, t] = sum_c dA[k, x, c, t] M[c, j, t]
        return np.einsum("kxct,cjt->kxjt", dA, self._M, optimize=True)

    def solve_frame_deltas(self, frame_deltas: np.ndarray, anchor_values: np.ndarray | None = None,
                           extra_targets: np.ndarray | None = None) -> np.ndarray:
        """Vertex deltas whose triangle edges best match the given frame edge columns.

        Parameters
        ----------
        frame_deltas : (k, 3, 2, m) frame edge columns (:meth:`transferred_frame_deltas`)
        anchor_values : (k, a, 3) deltas at :attr:`anchors` (default 0; :meth:`anchor_values`)
        extra_targets : (k*3, r) targets of the extra rows, row ``3 i + x`` = coordinate x of
            shape i (:meth:`virtual_edge_cols`); required with virtual edges or an extra operator

        Returns
        -------
        deltas : (k, n, 3)
        """
        k, m = frame_deltas.shape[0], frame_deltas.shape[-1]
        # EdgePoisson.solve_frame_rows takes one problem per column: (2m, 3k), (a, 3k), (r, 3k)
        cols = np.ascontiguousarray(frame_deltas, dtype=np.float64).reshape(k * 3, 2 * m)
        rows = np.ascontiguousarray(cols.T)
        a_rows = None
        if anchor_values is not None:  # (k, a, 3) -> (a, k*3)
            a_rows = np.ascontiguousarray(np.moveaxis(anchor_values, 2, 1).reshape(k * 3, -1).T)
        x_rows = None if extra_targets is None else np.ascontiguousarray(np.asarray(extra_targets).T)
        out = self.poisson.solve_frame_rows(rows, a_rows, x_rows)  # (n, k*3)
        return np.moveaxis(out.T.reshape(k, 3, -1), 1, 2)

    def virtual_edge_cols(self, deltas: np.ndarray | None = None, frame_deltas=None) -> np.ndarray | None:
        """Targets of the virtual-edge rows for template shapes ``deltas`` (k, n, 3), laid out as
        ``extra_targets`` (k*3, e) of :meth:`solve_frame_deltas`; None without virtual edges.
        ``frame_deltas`` (k, 3, 3, m): those shapes' ``A_i^S - A_0^S`` if already computed."""
        if self.virtual_edges is None or self.poisson.extra_operator is None:
            return None
        D = self.template.deltas if deltas is None else deltas
        T = self.virtual_edges.targets(self.template.neutral, D, self.target_neutral, self.template.faces,
                                       self.virtual_mode, self.template_frames, frame_deltas)  # (k, e, 3)
        return np.ascontiguousarray(np.moveaxis(T, 2, 1)).reshape(len(D) * 3, -1)

    def anchor_values(self, deltas: np.ndarray | None = None) -> np.ndarray:
        """Template deltas at the anchors, (k, a, 3): zero at still vertices."""
        D = self.template.deltas if deltas is None else deltas
        return D[:, self.anchors]

    def transfer(self, names=None) -> Rig:
        """Transfer every template shape (or those named) onto the target neutral."""
        idx = np.arange(self.template.n_shapes) if names is None else self.template.index(list(names))
        if self.poisson.extra_operator is not None and self.virtual_edges is None:
            raise InputError("transfer(): this transfer was built with an extra operator; pass its targets to "
                             "solve_frame_deltas(..., extra_targets=...)")
        out = np.empty((len(idx),) + self.template.neutral.shape)
        step = len(idx) if self.virtual_edges is not None else SHAPES_PER_SOLVE
        from ..progress import progress

        with progress(total=len(idx), desc="transferring") as bar:
            for s in range(0, len(idx), max(step, 1)):  # groups of shapes: memory reused, not re-faulted
                D = self.template.deltas[idx[s:s + step]]
                dA = frames_cm(self.template.neutral + D, self.template.faces)  # A_i^S - A_0^S, once for both uses
                dA -= self.template_frames
                out[s:s + step] = self.solve_frame_deltas(self.transferred_frame_deltas(D, frame_deltas=dA),
                                                          self.anchor_values(D), self.virtual_edge_cols(D, frame_deltas=dA))
                bar.update(len(D))
        return Rig(self.target_neutral, self.template.faces,
                   tuple(self.template.names[i] for i in idx), out, source="deformation transfer",
                   layout=self.template.layout)


def deformation_transfer(template: Rig, target_neutral: np.ndarray, anchors=None, virtual_edges=None,
                         virtual_weight: float | None = None, virtual_mode: str = "proportional") -> Rig:
    """Transfer every blendshape of ``template`` onto ``target_neutral`` (one-off call).

    Parameters
    ----------
    template : Rig with neutral ``S_0`` (n, 3), faces (m, 3) and deltas (k, n, 3)
    target_neutral : (n, 3) ``B_0``, same topology and vertex order
    anchors : optional anchor vertices fixing each component's translation
    virtual_edges, virtual_weight, virtual_mode : optional virtual-edge energy (Li et al. 2023), see
        :class:`DeformationTransfer`

    Returns
    -------
    Rig with neutral ``B_0`` and the transferred deltas ``B_i - B_0``; transferring onto
    ``S_0`` itself returns the template's shapes.
    """
    return DeformationTransfer(template, target_neutral, anchors, virtual_edges=virtual_edges,
                               virtual_weight=virtual_weight, virtual_mode=virtual_mode).transfer()
