"""Inner lips: iBUG-68 inner-lip points placed from their outer-lip partners (tracker option
``inner_lips="follow"``, beyond the paper).

Closed lips put an upper and a lower inner-lip point on the same pixel, so Lucas-Kanade centred on
the lip line moves both alike and the tracked mouth does not open. Instead each inner point
(61-63, 65-67) is its outer partner across the same lip (50-52, 56-58, :data:`.landmarks.INNER_LIP_PARTNERS`)
plus the first frame's lip-thickness offset, turned and scaled with the outer lip (a 2D similarity
in complex form); per-frame detections renew the offset.
"""

from __future__ import annotations

import numpy as np

#: values of ``TrackerOptions.inner_lips``
INNER_LIPS = ("follow", "track", "auto")
#: weight of a detection's own lip thickness in the running offset of ``inner_lips="follow"``
LIP_RENEW = 0.3


def _to_complex(p: np.ndarray) -> np.ndarray:
    return p[..., 0] + 1j * p[..., 1]


def _from_complex(z: np.ndarray) -> np.ndarray:
    return np.stack([z.real, z.imag], -1)


def similarity_factor(ref: np.ndarray, cur: np.ndarray) -> complex:
    """Complex factor a (scale times rotation) of the least-squares similarity ``cur ~= a ref + b`` of
    two (n, 2) point sets (Umeyama in 2D: ``a = sum conj(z_ref) z_cur / sum |z_ref|^2``, centred)."""
    z0 = _to_complex(ref - ref.mean(0))
    z1 = _to_complex(cur - cur.mean(0))
    den = float(np.sum(np.abs(z0) ** 2))
    return complex(np.sum(np.conj(z0) * z1) / den) if den > 0 else 1.0 + 0.0j


def follow_outer_lip(partners: np.ndarray, offset: np.ndarray, a: complex) -> np.ndarray:
    """Inner-lip points (P, 2) = outer-lip partners (P, 2) + the frame-0 offsets (P, 2) turned and
    scaled by the complex factor ``a`` of :func:`similarity_factor`."""
    return partners + _from_complex(a * _to_complex(offset))


__all__ = ["INNER_LIPS", "LIP_RENEW", "similarity_factor", "follow_outer_lip"]
