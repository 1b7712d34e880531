"""The check of a pose found by the similarity search (:mod:`.rigid`), reported per scan, never silent.

Two signs of a doubtful pose:

* **coverage**: the share of the scan's points within ``near`` (a fraction of the template's RMS
  radius, in the scan's units through the found scale) of the placed template. Every point of a scan
  of the template's kind has a counterpart on the template; a wrong pose leaves many without one.
* **ambiguity**: the search refines several distinct candidates; when one ends at a pose whose rotation
  differs from the best by more than ``distinct_degrees`` with a scan-to-template residual within
  ``ambiguous_ratio`` of the best, the data do not decide between them (a symmetric shape, a scan
  showing too little of the face). With a known start (landmarks, a registered neutral) there are no
  candidates and the pose is not called ambiguous.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree



def _angle(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


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
        return {"near_share": float(self.near_share), "runner_up_degrees": float(self.runner_up_degrees),
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


def pose_check(refined: list, candidates: int, T_tree: cKDTree, scan_pts: np.ndarray, rt: float, options
               ) -> RigidResult:
    """The best of the refined poses and its check.

    Parameters
    ----------
    refined : (similarity, scan-to-template residual in scan units) of each refined start
    candidates : the first ``candidates`` of them come from distinct search candidates; only these
        are runner-ups (the others restart near the best: a flat basin, not a second pose)
    T_tree : tree of template points (template frame)
    scan_pts : (q, 3) scan points
    rt : the template's RMS radius (template units)
    options : the search's :class:`~facebasis.geometry.rigid.RigidOptions`
    """
    res = np.array([r for _, r in refined])
    i = int(np.argmin(res))
    best = refined[i][0]
    ang = np.array([_angle(s.rotation @ best.rotation.T) for s, _ in refined])
    other = (ang > options.distinct_degrees) & (np.arange(len(refined)) < candidates)
    j = int(np.argmin(np.where(other, res, np.inf))) if other.any() else -1
    ratio = float(res[j] / max(res[i], 1e-300)) if j >= 0 else np.inf
    d, _ = T_tree.query(best.inverse().apply(scan_pts))
    near = float(np.mean(d < options.near * rt))
    k = max(3, int(round(options.keep_scan * len(d))))
    score = float(np.sqrt(np.mean(np.partition(d, min(k, len(d)) - 1)[:k] ** 2)))
    ambiguous = ratio < options.ambiguous_ratio
    return RigidResult(best, score, near, float(ang[j]) if j >= 0 else float("nan"), ratio, ambiguous,
                       ambiguous or near < options.min_near_share, options.min_near_share)
