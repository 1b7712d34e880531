"""problems.clip_readback: the clip's motion replayed one feature at a time, on tiny data built here."""

from types import SimpleNamespace

import numpy as np

from facebasis.defaults.cartoon import cartoon_landmarks
from problems.bench_cartoon import FEATURES, features
from problems.clip_readback import GROUPS, replay_rows


def _motion(T=6, seed=0):
    """(T, 68, 2) the default cartoon's landmarks (on a 128 px canvas) with every point moving (frame 0 at rest)."""
    lm = cartoon_landmarks() / 4.0
    rng = np.random.default_rng(seed)
    P = lm[None] + 0.6 * rng.standard_normal((T, 68, 2))
    P[0] = lm
    return lm, P


def test_lower_lip_and_brow_groups_move_their_own_measure_only():
    lm, P = _motion()
    for name, idx in (("mouth_open", 0), ("brow_height", 2)):
        Q = np.repeat(lm[None], len(P), axis=0)
        Q[:, GROUPS[name]] = P[:, GROUPS[name]]
        F = np.array([features(x) for x in Q])
        moved = np.ptp(F, axis=0)
        assert moved[idx] > 1e-3
        assert np.all(np.delete(moved, idx) < 1e-12), (name, moved)
    assert set(GROUPS) == set(FEATURES)


class _FixedReader:
    """A detector stub: the same 68 points whatever the picture."""

    def __init__(self, lm):
        self.lm = lm

    def detect(self, frame):
        assert frame.ndim == 3 and frame.dtype == np.uint8
        return self.lm.copy()


def test_replay_rows_one_row_per_reader_and_measure():
    from scipy.spatial import Delaunay

    lm, P = _motion()
    image = np.full((128, 128, 3), 200, np.uint8)
    cap = SimpleNamespace(landmarks=P, vertices=P, faces=Delaunay(lm).simplices)
    rows = replay_rows(cap, "clip", "grey", image, lm, {"stub": _FixedReader(lm)}, np.arange(len(P)),
                       {"stub": np.full(4, 0.01)})
    assert [r["feature"] for r in rows] == list(FEATURES)
    for r in rows:
        assert r["frames"] == len(P) and r["detected"] == len(P)
        assert r["sd_warp"] > 0 and 0 < r["floor"] < 1
        assert not abs(r["r_clip"]) > 1e-6 and np.isnan(r["box_other"])      # a constant reading follows nothing


def test_summary_takes_the_median_over_the_clips():
    from problems.clip_readback import SUMMARY, summary_rows

    base = {c: float("nan") for c in SUMMARY}
    rows = [{**base, "clip": c, "image": "a", "reader": "dlib", "feature": "eye_open", "r_clip": v, "floor": 0.9}
            for c, v in (("x", 0.1), ("y", 0.5), ("z", 0.3))]
    rows.append({**base, "clip": "x", "image": "b", "reader": "dlib", "feature": "eye_open", "r_clip": 0.7})
    out = summary_rows(rows)
    assert [(r["image"], r["clips"]) for r in out] == [("a", 3), ("b", 1)]
    assert out[0]["r_clip"] == 0.3 and out[0]["floor"] == 0.9 and np.isnan(out[0]["r_alone"])
