"""Example-based generation problems on the ICT data with a known person-specific ground truth.

The construction is :mod:`facebasis.rigging.synthetic`'s; ``ict_person_problem`` builds, from the ICT data
(``../shared``):

* a target identity ``B_0`` (seeded identity weights);
* a person-specific rig that differs from the template as a real person's would: deformation
  transfer of ICT's expressions onto ``B_0``, then per shape a strength in [0.7, 1.4], a left/right
  asymmetry, a smooth spatial modulation of the motion (the person's own muscle pattern, not a
  rescaling), and couplings (the smile pulls the cheek up, the jaw opening drags the lower lip);
* training expressions: sparse combinations of 2-5 shapes of that rig, covering every shape,
  respecting the exclusive pairs; rough initial weights = truth + uniform noise, clipped to [0, 1];
* held-out expressions made the same way, for measuring how well a rig reproduces unseen
  expressions (weights refitted).
"""

from __future__ import annotations

from facebasis.rigging.synthetic import PersonProblem, default_face_problem, make_person_problem, personalise  # noqa: F401

ICT_EXCLUSIVE = (
    ("mouthLeft", "mouthRight"), ("jawLeft", "jawRight"), ("eyeLookIn_L", "eyeLookOut_L"),
    ("eyeLookIn_R", "eyeLookOut_R"), ("eyeLookUp_L", "eyeLookDown_L"), ("eyeLookUp_R", "eyeLookDown_R"),
    ("mouthSmile_L", "mouthFrown_L"), ("mouthSmile_R", "mouthFrown_R"), ("eyeBlink_L", "eyeWide_L"),
    ("eyeBlink_R", "eyeWide_R"),
)

ICT_COUPLINGS = (("mouthSmile_L", "cheekSquint_L", 0.4), ("mouthSmile_R", "cheekSquint_R", 0.4),
                 ("jawOpen", "mouthLowerDown_L", 0.2), ("jawOpen", "mouthLowerDown_R", 0.2),
                 ("browInnerUp_L", "browOuterUp_L", 0.25), ("browInnerUp_R", "browOuterUp_R", 0.25))


def ict_person_problem(seed: int = 0, n_train: int = 20, n_heldout: int = 20, noise: float = 0.3) -> PersonProblem:
    from facebasis.geometry.transfer import deformation_transfer
    from problems.ict import ict_random_identity, ict_rig

    template = ict_rig()
    _, B0 = ict_random_identity(seed)
    truth = personalise(deformation_transfer(template, B0), seed=seed, couplings=ICT_COUPLINGS)
    return make_person_problem(template, truth, ICT_EXCLUSIVE, n_train, n_heldout, noise, seed)
