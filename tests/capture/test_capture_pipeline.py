"""capture's background threads (facebasis.capture.pipeline): same results as a serial run, errors and
interrupts from either side stop the run cleanly, process-wide settings restored."""

import sys
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest

from facebasis.capture import capture, read_capture, synthetic_sequence
from facebasis.capture.overlay import OverlayWriter
from facebasis.capture.pipeline import FrameReader, OverlayThread
from facebasis.errors import InputError

from conftest import write_mp4

VIDEO_DIR = Path(__file__).resolve().parents[2].parent / "shared/data/video"


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    seq = synthetic_sequence(16, size=(128, 128))
    path = tmp_path_factory.mktemp("pipe") / "clip.mp4"
    w = OverlayWriter(path, 25, (128, 128))
    for f in seq.frames:
        w.write(f)
    w.close()
    return path, seq


def _pipeline_threads():
    return [t for t in threading.enumerate() if t.name.startswith("facebasis-capture-")]


def _same(a, b):
    for k in ("landmarks", "vertices", "lost"):
        assert np.array_equal(getattr(a, k), getattr(b, k)), k


def test_threads_give_bitwise_the_serial_result(tmp_path, clip):
    path, seq = clip
    a = capture(path, landmarks=seq.landmarks[0], out=tmp_path / "t", threads=True)
    b = capture(path, landmarks=seq.landmarks[0], out=tmp_path / "s", threads=False)
    _same(a, b)
    assert (tmp_path / "t/landmarks.csv").read_bytes() == (tmp_path / "s/landmarks.csv").read_bytes()
    _same(read_capture(tmp_path / "t"), read_capture(tmp_path / "s"))
    assert a.capture.n_frames == 16 and not _pipeline_threads()


class _Detector:
    """A fake detector: the seeded landmarks plus noise, recording where and how it was called."""

    def __init__(self, seq, needs_near):
        self.seq, self.needs_near, self.calls = seq, needs_near, []

    def detect(self, frame, near=None):
        i = len(self.calls)
        self.calls.append((threading.current_thread().name, near is not None))
        return self.seq.landmarks[i] + np.random.default_rng(i).normal(0, 0.5, self.seq.landmarks[i].shape)


@pytest.mark.parametrize("needs_near", [False, True])
def test_a_detector_runs_ahead_only_when_it_ignores_the_track(clip, needs_near):
    path, seq = clip
    runs = []
    for threads in (True, False):
        det = _Detector(seq, needs_near)
        runs.append(capture(path, detector=det, threads=threads))
        assert len(det.calls) == 16
        names = {name for name, _ in det.calls[1:]}
        if threads and not needs_near:
            assert names == {"facebasis-capture-reader"} and not any(n for _, n in det.calls)
        else:
            assert names == {threading.main_thread().name}
            assert [n for _, n in det.calls] == [False] + [needs_near] * 15   # frame 0 has no track yet
    _same(*runs)


def test_reader_error_is_raised_in_the_caller_and_nothing_is_written(tmp_path, clip, monkeypatch):
    import facebasis.capture.video as video

    path, seq = clip
    real = video._video_frames

    def failing(*a, **k):
        for i, f in enumerate(real(*a, **k)):
            if i == 5:
                raise InputError("video x: frame 5 broke")
            yield f

    monkeypatch.setattr(video, "_video_frames", failing)
    with pytest.raises(InputError, match="frame 5 broke"):
        capture(path, landmarks=seq.landmarks[0], out=tmp_path / "o")
    assert not (tmp_path / "o").exists() and not _pipeline_threads()


def test_overlay_error_is_raised_in_the_caller(tmp_path, clip, monkeypatch):
    path, seq = clip
    calls = []

    def write(self, rgb):
        calls.append(1)
        if len(calls) == 3:
            raise OSError(28, "No space left on device")

    monkeypatch.setattr(OverlayWriter, "write", write)
    with pytest.raises(OSError, match="No space left"):
        capture(path, landmarks=seq.landmarks[0], out=tmp_path / "o")
    assert not (tmp_path / "o").exists() and not _pipeline_threads()


def test_interrupt_stops_the_threads_and_restores_settings(tmp_path, clip):
    path, seq = clip
    n, interval = cv2.getNumThreads(), sys.getswitchinterval()

    def progress(done, total):
        if done == 4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        capture(path, landmarks=seq.landmarks[0], out=tmp_path / "o", progress=progress)
    assert not (tmp_path / "o").exists() and not _pipeline_threads()
    assert cv2.getNumThreads() == n and sys.getswitchinterval() == interval


def test_reader_and_overlay_thread_units():
    secs = {"decode": 0.0, "detect": 0.0, "output": 0.0}
    frames = (np.full((4, 4, 3), i, np.uint8) for i in range(7))
    r = FrameReader(frames, lambda f: f[0, 0, :2].astype(float)[None], secs, detect_first=False, depth=2)
    got = list(r)
    assert [int(f[0, 0, 0]) for f, _ in got] == list(range(7))
    assert got[0][1] is None and [int(d[0, 0]) for _, d in got[1:]] == list(range(1, 7))
    assert list(r) == []             # exhausted stays exhausted
    r.close()

    class W:
        def __init__(self):
            self.frames, self.closed = [], False

        def write(self, img):
            self.frames.append(img)

        def close(self):
            self.closed = True

    w = W()
    o = OverlayThread(w, np.array([[0, 1, 2]]), secs)
    for i in range(5):
        o.put(np.zeros((8, 8, 3), np.uint8), np.array([[1.0, 1], [5, 1], [1, 5]]), np.array([[2.0, 2]]))
    o.close()
    assert len(w.frames) == 5 and w.closed and secs["output"] > 0


def test_the_write_error_is_reported_when_closing_the_writer_fails_too():
    """A writer that failed (disk full) usually fails to close as well: the first error is raised."""
    class W:
        def write(self, img):
            raise OSError("No space left on device")

        def close(self):
            raise ValueError("cannot close a broken stream")

    o = OverlayThread(W(), np.array([[0, 1, 2]]), {"output": 0.0})
    o.put(np.zeros((8, 8, 3), np.uint8), np.array([[1.0, 1], [5, 1], [1, 5]]), np.array([[2.0, 2]]))  # queued
    with pytest.raises(OSError, match="No space left"):
        o.close()


def test_overlapping_runs_restore_the_settings_found_by_the_first():
    from facebasis.capture.pipeline import thread_settings

    n, interval = cv2.getNumThreads(), sys.getswitchinterval()
    a, b = thread_settings(True), thread_settings(True)
    a.__enter__()
    b.__enter__()
    a.__exit__(None, None, None)     # the first run ends while the second still runs
    assert cv2.getNumThreads() == 1  # the second run keeps its settings
    b.__exit__(None, None, None)
    assert cv2.getNumThreads() == n and sys.getswitchinterval() == interval


@pytest.mark.skipif(not (VIDEO_DIR / "cap13_edit2.mp4").exists(), reason="shared clip not available")
def test_mediapipe_threaded_capture_is_the_serial_one(tmp_path):
    pytest.importorskip("mediapipe")
    video = VIDEO_DIR / "cap13_edit2.mp4"
    a = capture(video, detector="mediapipe", max_frames=40, threads=True)
    b = capture(video, detector="mediapipe", max_frames=40, threads=False)
    _same(a, b)


@pytest.mark.parametrize("threads", [True, False])
def test_a_cut_video_warns_once_in_the_calling_thread(tmp_path, threads):
    import warnings

    from facebasis.capture.video import VideoWarning

    seq = synthetic_sequence(24, size=(128, 128))
    full = write_mp4(tmp_path / "full.mp4", seq.frames)
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(full.read_bytes()[: full.stat().st_size * 2 // 3])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = capture(cut, landmarks=seq.landmarks[0], threads=threads)
    mine = [w for w in caught if issubclass(w.category, VideoWarning)]
    n = res.capture.n_frames
    assert 0 < n < 24 and len(mine) == 1
    assert f"decoded {n} frames, its container announced 24" in str(mine[0].message)


@pytest.mark.parametrize("bad", ["no", 1, None])
def test_threads_bad_values_are_one_line(tmp_path, clip, bad):
    path, seq = clip
    with pytest.raises(InputError, match=r"^threads: expected True or False, found .*$"):
        capture(path, landmarks=seq.landmarks[0], out=tmp_path / "o", threads=bad)
    assert not (tmp_path / "o").exists()
