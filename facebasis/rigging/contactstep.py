"""Exact contact after example-based generation: the generated shapes made intersection-free.

The rig of :func:`~facebasis.rigging.generation.generate_blendshapes` is corrected shape by shape
by :func:`facebasis.contact.exact.contact_correct` (Li, Shen, Liu 2023 extended to an exact
guarantee: no triangle pair intersects in a generated shape unless it intersects in the target
neutral or in the template shape; checked by the package's exact counter after every solve). A shape
the smallest-displacement rounds leave with pairs is solved again with the transfer energy
(``fallback`` in its report), and pairs still left then are removed by pulling the shape back
towards the target neutral around them (``retreated``), so the exact check ends clean. The
stored weights must then be the certified optimum of eq. 5 (Gao et al. 2015) for the shapes
actually written, so the final weight step is solved once more at the run's final lambda and the
training residuals are recomputed. The contact inputs are checked before generation by
:func:`facebasis.contact.exact.check_contact_inputs`.
"""

from __future__ import annotations

from .certify import certify_problem
from .problem import GenerationResult
from .weightproblem import WeightProblem


def contact_generation(generator, result: GenerationResult, exclude=(),
                       allow_target_pairs: bool = False, **contact_options):
    """Correct a generation result for exact contact and re-solve its final weight step.

    Parameters
    ----------
    generator : the :class:`~facebasis.rigging.generation.BlendshapeGenerator` that made ``result`` (its transfer energy smooths
        the correction; its examples, prior, pairs and unobserved shapes define the weight step).
    result : the generation result; its rig's neutral is the target neutral ``B_0``.
    exclude : shape names left as generated (correctives meant to press layers together).
    allow_target_pairs : accept a target neutral that intersects itself where the template neutral
        does not (those pairs stay allowed); otherwise that is an :class:`InputError` naming them.
    contact_options : passed to :func:`facebasis.contact.exact.contact_correct` (``stiffness``,
        ``max_iterations``, ``workers``, ...).

    Returns
    -------
    (contact, result) : the :class:`~facebasis.contact.exact.ContactResult` (per-shape rounds, QP
        iterations, smallest distance kept, pairs left; ``contact.ok``) and the result with the
        corrected rig, the re-solved weights (m, k), residuals (m,) and missing examples.
    """
    from ..contact.exact import contact_correct

    contact = contact_correct(result.rig, generator.problem.template, transfer=generator.dt, exclude=exclude,
                              allow_target_pairs=allow_target_pairs, **contact_options)
    final_lam = result.final_step[1]   # the lambda of the last alternation actually run
    problem = WeightProblem.from_rig(contact.rig, generator.problem.examples, generator.pairs,
                                     generator.problem.initial_weights, final_lam)
    weights = certify_problem(problem, free=generator.free).X
    return contact, result.with_weights(contact.rig, weights, generator.problem)


__all__ = ["contact_generation"]
