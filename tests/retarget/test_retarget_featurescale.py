"""Expression amplitude on the target's own proportions (eq. 12 per feature): a known mouth opening and
eye closing carried over proportionally, the maps, their bounds and their errors."""

import numpy as np
import pytest
from scipy.spatial import Delaunay

from facebasis.defaults.cartoon import default_cartoon
from facebasis.errors import InputError
from facebasis.retarget.featurescale import FEATURES_68, feature_maps, parse_amplitude
from facebasis.retarget.warp2d import CartoonAnimator

T = 60
INNER_UP, INNER_LO = [61, 62, 63], [67, 66, 65]
R_EYE_UP, R_EYE_LO = [37, 38], [41, 40]


def _gap(P, up, lo):
    """Mean vertical gap (T,) between landmark rows ``up`` and ``lo`` of points (T, 68, 2)."""
    return (P[:, lo, 1] - P[:, up, 1]).mean(1)


def _enlarge(lm, idx, factor):
    """Landmarks with the points ``idx`` scaled by ``factor`` about their centre."""
    out = lm.copy()
    c = lm[idx].mean(0)
    out[idx] = c + factor * (lm[idx] - c)
    return out


def _capture(rest, opening, eye_closing, seed=0):
    """A synthetic capture (T, 68, 2): the inner lips part by ``opening`` (T,) pixels (the lower lip
    and the jaw's chin follow), the right eye's lids move towards each other by ``eye_closing`` (T,)
    (each lid half of it), and the whole head moves by a similarity per frame (scale 0.9-1.1,
    rotation +-5 degrees, shift up to 12 px) that the drive must take out."""
    P = np.repeat(rest[None], T, axis=0)
    P[:, np.r_[INNER_LO, 55:60], 1] += opening[:, None]
    P[:, 6:11, 1] += opening[:, None]
    P[:, R_EYE_UP, 1] += 0.5 * eye_closing[:, None]
    P[:, R_EYE_LO, 1] -= 0.5 * eye_closing[:, None]
    t = np.linspace(0, 1, T)
    rho = 1 + 0.1 * np.sin(2 * np.pi * t)
    th = np.deg2rad(5) * np.sin(4 * np.pi * t)
    a = rho * np.exp(1j * th)
    b = 12 * np.cos(2 * np.pi * t) + 6j * np.sin(2 * np.pi * t)
    c0 = rest.mean(0)
    z = (P[..., 0] - c0[0]) + 1j * (P[..., 1] - c0[1])
    z = a[:, None] * z + b[:, None] + complex(*c0)
    return np.stack([z.real, z.imag], -1)


@pytest.fixture(scope="module")
def setting():
    face = default_cartoon(256)
    cap_rest = face.landmarks.copy()
    # the target: the same face with a mouth and a right eye twice as large (a cartoon's proportions)
    target = _enlarge(_enlarge(cap_rest, np.r_[48:68], 2.0), np.r_[36:42], 2.0)
    t = np.linspace(0, 1, T)
    opening = 8.0 * np.sin(np.pi * t) ** 2 + 2.0 * np.sin(6 * np.pi * t) ** 2     # pixels, known
    gap0 = _gap(cap_rest[None], R_EYE_UP, R_EYE_LO)[0]
    closing = 0.6 * gap0 * np.sin(3 * np.pi * t) ** 2                               # up to 60% shut
    P = _capture(cap_rest, opening, closing)
    faces = Delaunay(cap_rest).simplices
    return face, cap_rest, target, opening, closing, P, faces


@pytest.mark.parametrize("amplitude", ["feature", "uniform"])
def test_a_known_mouth_opening_drives_the_target_proportionally(setting, amplitude):
    face, cap_rest, target, opening, closing, P, faces = setting
    anim = CartoonAnimator(face.image, target, P[0], P[0], faces, amplitude=amplitude)
    still = anim.drive(P, P).still
    warped = _gap(still, INNER_UP, INNER_LO) - _gap(still[:1], INNER_UP, INNER_LO)
    assert np.corrcoef(warped, opening)[0, 1] > 0.95
    slope = np.polyfit(opening, warped, 1)[0]
    # "feature": the target's mouth is twice the capture's: it opens twice as far; "uniform": the
    # paper's one scale s (eq. 13, mean edge lengths), well below 2 here
    expect = 2.0 if amplitude == "feature" else anim.scale
    assert slope == pytest.approx(expect, rel=0.05)
    assert anim.scale < 1.5


@pytest.mark.parametrize("amplitude", ["feature", "uniform"])
def test_an_eye_closing_follows_the_eyes_own_size(setting, amplitude):
    face, cap_rest, target, opening, closing, P, faces = setting
    anim = CartoonAnimator(face.image, target, P[0], P[0], faces, amplitude=amplitude)
    still = anim.drive(P, P).still
    g_cap = _gap(cap_rest[None], R_EYE_UP, R_EYE_LO)[0]
    g_tgt = _gap(still[:1], R_EYE_UP, R_EYE_LO)[0]
    rel_cap = closing / g_cap                                  # fraction of the eye shut on the capture
    rel_tgt = 1 - _gap(still, R_EYE_UP, R_EYE_LO) / g_tgt     # ... and on the target
    assert np.corrcoef(rel_tgt, rel_cap)[0, 1] > 0.95
    slope = np.polyfit(rel_cap, rel_tgt, 1)[0]
    if amplitude == "feature":    # the target's eye (twice as tall) shuts by the same fraction
        assert slope == pytest.approx(1.0, rel=0.05)
    else:                         # the paper's: by s / 2 of it, half-way at best
        assert slope == pytest.approx(anim.scale / 2.0, rel=0.05)


def test_an_eye_shut_on_the_capture_closes_on_the_target_without_folding():
    face = default_cartoon(256)
    rest = face.landmarks.copy()
    gap0 = _gap(rest[None], R_EYE_UP, R_EYE_LO)[0]
    closing = np.linspace(0, 1.3 * gap0, T)                 # the lids meet, then cross (tracking noise)
    P = _capture(rest, np.zeros(T), closing)
    target = _enlarge(rest, np.r_[36:42], 1.5)
    anim = CartoonAnimator(face.image, target, P[0], P[0], Delaunay(rest).simplices)
    drive = anim.drive(P, P)
    g = _gap(drive.still, R_EYE_UP, R_EYE_LO) / _gap(drive.still[:1], R_EYE_UP, R_EYE_LO)[0]
    # closed down to the smallest gap the warp allows (sigma_lo = 15% of the rest gap), never crossed
    assert g[-1] == pytest.approx(anim.solver.sigma_lo, abs=0.03)
    assert g.min() > 0
    assert all(anim.solver.area_ratios(np.concatenate([X, anim.ring])).min() > 0 for X in drive.still)


def test_feature_maps_measure_each_features_proportions_and_are_bounded():
    rest = default_cartoon(256).landmarks.copy()
    target = _enlarge(rest, np.r_[48:68], 2.0)                      # a mouth twice as large
    target[[37, 38], 1] -= 0.5 * (rest[[41, 40], 1] - rest[[37, 38], 1])   # a right eye 1.5x as tall
    th = np.deg2rad(30)                                              # the target turned 30 degrees, 1.5x
    R = 1.5 * np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    maps = feature_maps(rest, target @ R.T, 1.5)
    assert maps.names == tuple(f[0] for f in FEATURES_68)
    ratios = dict(zip(maps.names, maps.ratios))
    np.testing.assert_allclose(ratios["mouth"], [3.0, 3.0], atol=1e-9)
    np.testing.assert_allclose(ratios["right eye"], [1.5, 2.25], rtol=1e-3)   # its corners are not level
    np.testing.assert_allclose(ratios["left eye"], [1.5, 1.5], atol=1e-9)
    # a displacement turns with the target: d @ map = R (ratio-scaled d) for a row vector d
    D = np.random.default_rng(0).normal(size=(3, 68, 2))
    out = maps.apply(D)
    np.testing.assert_allclose(out[:, 48:68], 2.0 * D[:, 48:68] @ R.T, atol=1e-9)
    np.testing.assert_allclose(out[:, 42:48], D[:, 42:48] @ R.T, atol=1e-9)
    np.testing.assert_allclose(out[:, :17], 1.5 * D[:, :17])                 # the jaw keeps eq. 12's s
    # a brow moves with its eye's centre, and by its own map relative to it (the face's s since 859b1c2):
    # its height over the eye does not depend on what the eye's lids do
    rel = out[:, 17:22] - out[:, 36:42].mean(1, keepdims=True)
    np.testing.assert_allclose(rel, (D[:, 17:22] - D[:, 36:42].mean(1, keepdims=True)) @ maps.maps[2], atol=1e-9)
    # an eye nearly shut on the capture's first frame (a tenth of its height: the target's lids
    # would move 10 s) cannot blow the lid motion up: bounded to 3 s; shut flat: the bound as well
    for k in (0.1, 0.0):
        flat = rest.copy()
        c = flat[36:42, 1].mean()
        flat[36:42, 1] = c + k * (flat[36:42, 1] - c)
        np.testing.assert_allclose(feature_maps(flat, rest * 1.5, 1.5).ratios[0], [1.5, 4.5], rtol=1e-2)
    np.testing.assert_allclose(feature_maps(flat, flat, 1.0).ratios[0], [1.0, 1.0])   # flat on both: s


def test_bad_amplitude_and_bad_maps_inputs():
    face = default_cartoon(256)
    lm = face.landmarks
    with pytest.raises(InputError, match="amplitude: expected one of feature, uniform, found 'loud'"):
        CartoonAnimator(face.image, lm, lm, lm, Delaunay(lm).simplices, amplitude="loud")
    with pytest.raises(InputError, match="amplitude"):
        parse_amplitude(3)
    assert parse_amplitude(None) == "feature" and parse_amplitude(" Uniform ") == "uniform"
    with pytest.raises(InputError, match="same shape"):
        feature_maps(lm, lm[:60], 1.0)
    with pytest.raises(InputError, match="scale > 0"):
        feature_maps(lm, lm, 0.0)


def test_feature_amplitude_without_the_68_points_says_it_uses_the_single_scale(tmp_path):
    """A capture of another landmark set cannot be split into eyes and mouth: the run says so and records
    the mode it used."""
    import json

    import cv2

    from facebasis.capture.trackfile import write_capture
    from facebasis.defaults.cartoon import default_cartoon
    from facebasis.retarget.pipeline import run_animate2d
    from facebasis.retarget.synthetic import capture_from_landmarks

    face = default_cartoon()
    keep = np.arange(0, 68, 2)                                   # 34 of the 68 points
    L0 = face.landmarks[keep]
    t = np.arange(6)[:, None, None]
    L = L0[None] + 2.0 * np.sin(t + L0[None, :, :1] / 50.0)      # a small smooth motion, 6 frames
    write_capture(tmp_path / "cap", capture_from_landmarks(L, fps=25.0, size=(512, 512)))
    cv2.imwrite(str(tmp_path / "c.png"), face.image[..., ::-1])
    (tmp_path / "c.json").write_text(json.dumps(L0.tolist()))
    said = []
    run_animate2d(tmp_path / "cap", tmp_path / "out", image=tmp_path / "c.png", landmarks=tmp_path / "c.json",
                  log=said.append)
    assert any("'feature' needs the 68 iBUG landmarks, found 34" in s for s in said)
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["amplitude"] == "uniform"


def test_the_animator_records_the_amplitude_it_uses():
    """Called from Python with a capture of another landmark set, the animator itself says that it uses
    the single scale."""
    from facebasis.defaults.cartoon import default_cartoon
    from facebasis.retarget.synthetic import capture_from_landmarks
    from facebasis.retarget.warp2d import CartoonAnimator

    face = default_cartoon()
    L0 = face.landmarks[np.arange(0, 68, 2)]
    cap = capture_from_landmarks(L0[None], fps=25.0, size=(512, 512))
    anim = CartoonAnimator(face.image, L0, cap.landmarks[0], cap.vertices[0], cap.faces, amplitude="feature")
    assert anim.amplitude == "uniform"
    assert CartoonAnimator(face.image, face.landmarks, face.landmarks, face.landmarks,
                           capture_from_landmarks(face.landmarks[None]).faces).amplitude == "feature"
