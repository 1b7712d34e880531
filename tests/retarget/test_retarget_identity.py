"""Identity calibration (``identity="auto"``, ``--identity``): a static landmark offset recovered from
the capture itself, the older first-frame spelling, and every bad value."""

import json

import numpy as np
import pytest

from facebasis.capture.trackfile import write_capture
from facebasis.defaults.face import EXCLUSIVE_PAIRS, default_template
from facebasis.defaults.face_landmarks import face_landmarks
from facebasis.errors import InputError
from facebasis.retarget.observe import landmark_jacobian
from facebasis.retarget.pipeline import run_retarget
from facebasis.retarget.rigdrive import RigRetargeter, resolve_identity
from facebasis.retarget.synthetic import capture_from_landmarks, smooth_weight_curves, synthetic_capture

ACTIVE = ("jawOpen", "mouthSmile_L", "mouthLeft", "eyeBlink_L", "eyeBlink_R", "browInnerUp")


def known_offset(rig, idx, scale: float = 0.15, seed: int = 4):
    """A static in-plane landmark offset (L, 3) the weights and the pose cannot produce (orthogonal to
    the shapes' and the pose's landmark motion at the neutral), plus a positive baseline of one shape
    (cheekPuff_L 0.35: a face whose cheeks sit like a slight puff all the time)."""
    rng = np.random.default_rng(seed)
    J = landmark_jacobian(rig, idx)                                   # (2L, k + 6), frontal
    Q, _ = np.linalg.qr(J)
    o = rng.normal(size=2 * len(idx))
    o = o - Q @ (Q.T @ o)
    o *= scale / np.sqrt(np.mean(o.reshape(-1, 2) ** 2) * 2)          # rms per landmark = scale
    perp = np.zeros((len(idx), 3))
    perp[:, 0], perp[:, 1] = o.reshape(-1, 2)[:, 0], -o.reshape(-1, 2)[:, 1]   # image y down -> rig y up
    base = np.zeros(rig.n_shapes)
    base[rig.names.index("cheekPuff_L")] = 0.35
    return perp, base


@pytest.fixture(scope="module")
def person():
    """A capture of a face whose neutral landmarks differ from the rig's by a known static offset."""
    rig, idx = default_template(), face_landmarks()
    perp, base = known_offset(rig, idx)
    X = smooth_weight_curves(rig.names, ACTIVE, 90, seed=5)
    neutral = rig.neutral.copy()
    neutral[idx] += perp
    neutral += np.tensordot(base, rig.deltas, axes=(0, 0))
    other = rig.with_neutral(neutral, rig.deltas, "the person")
    cap = synthetic_capture(other, idx, X, noise_px=0.0, seed=5, amplitude_deg=0.0)
    return rig, idx, X, perp, base, cap


def test_auto_recovers_a_known_static_offset_and_keeps_the_weights(person):
    rig, idx, X, perp, base, cap = person
    auto = RigRetargeter(rig, idx, EXCLUSIVE_PAIRS).run(cap.landmarks)          # identity "auto" is the default
    plain = RigRetargeter(rig, idx, EXCLUSIVE_PAIRS, identity="rig").run(cap.landmarks)
    cal = auto.calibration
    assert auto.identity == "auto" and cal is not None and cal.applied
    truth = perp + np.tensordot(base, rig.deltas[:, idx], axes=(0, 0))
    # the offset is determined up to what the pose absorbs: compare after the best similarity
    err = cal.offset[:, :2] - truth[:, :2]
    err = err - err.mean(0)
    assert np.sqrt(np.mean(err ** 2)) < 0.1 * np.sqrt(np.mean(truth[:, :2] ** 2))
    assert abs(cal.baseline[rig.names.index("cheekPuff_L")] - 0.35) < 0.03
    e_auto, e_plain = np.abs(auto.weights - X).mean(), np.abs(plain.weights - X).mean()
    assert e_auto < 0.003 and e_auto < 0.25 * e_plain          # measured 0.001 against 0.009
    assert cal.rms_after < 0.1 * cal.rms_before
    assert auto.residual.mean() < 0.2 * plain.residual.mean()


def test_auto_needs_no_neutral_first_frame(person):
    """The capture starts on an expression: the first-frame neutral reads it as the face, auto does not."""
    rig, idx, X, perp, base, _ = person
    Xs = X.copy()
    Xs[:8, rig.names.index("jawOpen")] = 0.7
    neutral = rig.neutral.copy()
    neutral[idx] += perp
    neutral += np.tensordot(base, rig.deltas, axes=(0, 0))
    cap = synthetic_capture(rig.with_neutral(neutral, rig.deltas, "p"), idx, Xs, noise_px=0.0, seed=5,
                            amplitude_deg=0.0)
    auto = RigRetargeter(rig, idx, EXCLUSIVE_PAIRS, identity="auto").run(cap.landmarks)
    first = RigRetargeter(rig, idx, EXCLUSIVE_PAIRS, identity="first-frame").run(cap.landmarks)
    assert np.abs(auto.weights - Xs).mean() < 0.01
    assert np.abs(first.weights - Xs).mean() > 3 * np.abs(auto.weights - Xs).mean()


def test_auto_on_the_rigs_own_face_changes_nothing():
    """Noise only (the rig's own face): the offset would only fit noise, so none is applied and the
    weights are exactly those of identity "rig"."""
    rig, idx = default_template(), face_landmarks()
    X = smooth_weight_curves(rig.names, ACTIVE, 60, seed=6)
    cap = synthetic_capture(rig, idx, X, noise_px=0.5, seed=6)
    auto = RigRetargeter(rig, idx, EXCLUSIVE_PAIRS, identity="auto").run(cap.landmarks)
    plain = RigRetargeter(rig, idx, EXCLUSIVE_PAIRS, identity="rig").run(cap.landmarks)
    assert not auto.calibration.applied
    assert np.array_equal(auto.calibration.offset, np.zeros((len(idx), 3)))
    np.testing.assert_allclose(auto.weights, plain.weights, atol=1e-12)


def test_identity_values_and_the_older_spelling():
    assert resolve_identity() == "auto"
    assert resolve_identity(None, True) == "first-frame"
    assert resolve_identity(None, False) == "rig"
    assert resolve_identity("first-frame", True) == "first-frame"
    with pytest.raises(InputError, match="identity: expected one of auto, first-frame, rig, quantile, found 'neutral'"):
        resolve_identity("neutral")
    with pytest.raises(InputError, match="found identity='auto' and first_frame_neutral=True"):
        RigRetargeter(default_template(), face_landmarks(), identity="auto", first_frame_neutral=True)
    assert RigRetargeter(default_template(), face_landmarks(), first_frame_neutral=True).identity == "first-frame"


def test_cli_identity_option(person, tmp_path, capsys):
    from facebasis.cli import main
    from facebasis.cli.common import flags_of

    rig, idx, X, perp, base, cap = person
    folder = tmp_path / "capture"
    write_capture(folder, capture_from_landmarks(cap.landmarks, fps=cap.fps, size=cap.size))
    assert main(["retarget", str(folder), "--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert "identity auto" in out and "static landmark offset estimated on 40 pilot frames" in out
    s = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert s["identity"] == "auto" and s["identity_rms_px_calibrated"] < 0.1 * s["identity_rms_px_rig_neutral"]
    assert main(["retarget", str(folder), "--out", str(tmp_path / "r"), "--identity", "rig"]) == 0
    assert json.loads((tmp_path / "r" / "summary.json").read_text())["identity"] == "rig"
    capsys.readouterr()
    assert main(["retarget", str(folder), "--out", str(tmp_path / "f"), "--first-frame-neutral"]) == 0
    assert "older spelling of --identity first-frame" in capsys.readouterr().out
    assert json.loads((tmp_path / "f" / "summary.json").read_text())["identity"] == "first-frame"
    assert main(["retarget", str(folder), "--out", str(tmp_path / "bad"), "--identity", "person"]) == 2
    assert "--identity: expected one of auto, first-frame, rig, quantile, found 'person'" in capsys.readouterr().err
    assert main(["retarget", str(folder), "--out", str(tmp_path / "bad"), "--identity", "rig",
                 "--first-frame-neutral"]) == 2
    assert "--first-frame-neutral: expected no other --identity, found --identity rig" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()
    with pytest.raises(InputError, match=r"^identity and first_frame_neutral: expected one setting, found "
                                         r"identity='rig' and first_frame_neutral=True") as ei:
        run_retarget(folder, tmp_path / "bad", identity="rig", first_frame_neutral=True)
    assert str(ei.value.renamed(flags_of("retarget"))).startswith("--identity and --first-frame-neutral: expected")


def test_span_basis_adds_no_direction_outside_a_rank_deficient_span():
    """The residual part of the calibration is projected off the shapes' landmark motion; with shapes
    the landmarks cannot tell apart that motion is rank-deficient, and the projection must remove
    only its span (QR would remove arbitrary extra directions)."""
    from facebasis.retarget.calibrate import span_basis

    rng = np.random.default_rng(0)
    M = rng.normal(size=(10, 2)) @ rng.normal(size=(2, 4))           # rank 2, four columns
    Q = span_basis(M)
    assert Q.shape == (10, 2)
    np.testing.assert_allclose(Q.T @ Q, np.eye(2), atol=1e-12)
    o = rng.normal(size=10)
    coef, *_ = np.linalg.lstsq(M, o, rcond=None)
    np.testing.assert_allclose(o - Q @ (Q.T @ o), o - M @ coef, atol=1e-10)   # the exact off-span part
    assert span_basis(np.zeros((5, 3))).shape == (5, 0)
