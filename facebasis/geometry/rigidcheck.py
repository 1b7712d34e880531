"""The check of a pose found by the similarity search (:mod:`.rigid`), reported per scan, never silent.

Two signs of a doubtful pose:

* **coverage**: the share of the scan's points within ``near`` (a fraction of the template's RMS
  radius, in the scan's units through the found scale) of the placed template. Every point of a scan
  of the template's kind has a counterpart on the template; a scan unlike the template (another
  object, much more than a head) leaves many without one.
* **ambiguity**: the search refines several distinct candidates; when one ends at a pose whose rotation
  differs from the best by more than ``distinct_degrees`` with a scan-to-template residual within
  ``ambiguous_ratio`` of the best, the data do not decide between them (a symmetric shape, a scan
  showing too little of the face). With a known start (landmarks given) there are no candidates and
  the pose is not called ambiguous.

What it cannot see: a search that missed the true basin altogether. The coverage is the residual the
search has just minimised, so a wrong pose that lays the template snugly on part of the scan passes
(measured: the lower half of a face found upside down, 0.88 of its points near the template, the
runner-up 2.6 times worse; a lower-face cut of an ICT person 4.6 degrees off, near share 0.81). The
check describes the similarity search's pose, before the final point-to-plane refinement.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

def rotation_angle(R: np.ndarray) -> float:
    """The angle (degrees) of a rotation (3, 3)."""
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


def trimmed(d: np.ndarray, keep: float) -> np.ndarray:
    """Indices of the ``max(3, round(keep * len(d)))`` smallest entries of ``d`` (all if fewer)."""
    k = max(3, int(round(keep * len(d))))
    return np.argpartition(d, k - 1)[:k] if k < len(d) else np.arange(len(d))


@dataclass(frozen=True)
class RigidResult:
    """The similarity search's pose and its check.

    Attributes
    ----------
    similarity : template -> scan similarity
    score : trimmed RMS scan-to-template residual in template units
    near_share : share of scan points within ``options.near * rt`` (template units) of the template
    runner_up_degrees : rotation between the best pose and the best distinct one (nan if none)
    runner_up_ratio : that pose's residual over the best's (inf if none); near 1: ambiguous
    ambiguous : ``runner_up_ratio < options.ambiguous_ratio``
    doubtful : ambiguous or ``near_share < options.min_near_share``
    """

    similarity: "Similarity"  # noqa: F821 (facebasis.geometry.rigid.Similarity)
    score: float
    near_share: float
    runner_up_degrees: float
    runner_up_ratio: float
    ambiguous: bool
    doubtful: bool
    min_near_share: float = 0.0

    def as_dict(self) -> dict:
        return {"scan_to_template_rms": float(self.score), "near_share": float(self.near_share), "runner_up_degrees": float(self.runner_up_degrees),
                "runner_up_ratio": float(self.runner_up_ratio), "ambiguous": bool(self.ambiguous),
                "doubtful": bool(self.doubtful)}

    def warning(self) -> str | None:
        """A one-line warning when the pose is doubtful, else None."""
        if not self.doubtful:
            return None
        why = []
        if self.ambiguous:
            why.append(f"a pose {self.runner_up_degrees:.0f} deg away fits nearly as well "
                       f"(residual ratio {self.runner_up_ratio:.2f})")
        if self.near_share < self.min_near_share:
            why.append(f"only {100 * self.near_share:.0f}% of the scan lies near the template")
        return "rigid pose doubtful: " + "; ".join(why)


def pose_check(refined: list, candidates: int, rt: float, options) -> RigidResult:
    """The best of the refined poses and its check.

    Parameters
    ----------
    refined : (similarity, scan-to-template residual in scan units, (q,) each scan point's distance to
        the template in template units at that similarity) of each refined start
    candidates : the first ``candidates`` of them come from distinct search candidates; only these
        are runner-ups (the others restart near the best: a flat basin, not a second pose)
    rt : the template's RMS radius (template units)
    options : the search's :class:`~facebasis.geometry.rigid.RigidOptions`
    """
    res = np.array([r for _, r, _ in refined])
    i = int(np.argmin(res))
    best, d = refined[i][0], refined[i][2]
    ang = np.array([rotation_angle(s.rotation @ best.rotation.T) for s, _, _ in refined])
    other = (ang > options.distinct_degrees) & (np.arange(len(refined)) < candidates)
    j = int(np.argmin(np.where(other, res, np.inf))) if other.any() else -1
    ratio = float(res[j] / max(res[i], 1e-300)) if j >= 0 else np.inf
    near = float(np.mean(d < options.near * rt))
    score = float(np.sqrt(np.mean(d[trimmed(d, options.keep_scan)] ** 2)))
    ambiguous = ratio < options.ambiguous_ratio
    return RigidResult(best, score, near, float(ang[j]) if j >= 0 else float("nan"), ratio, ambiguous,
                       ambiguous or near < options.min_near_share, options.min_near_share)
