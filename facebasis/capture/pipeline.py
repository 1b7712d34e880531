"""Background threads of :func:`facebasis.capture.capture`: frames decoded and detected ahead of the
tracker, the overlay drawn and encoded behind it.

The tracker itself is sequential (each frame starts from the last), but decoding a frame and running
a detector that does not look at the track (MediaPipe follows the face by itself) do not depend on
it, and neither does drawing and encoding the overlay of a frame already tracked. :class:`FrameReader`
runs the first two in a thread a few frames ahead, :class:`OverlayThread` the last behind; the
tracker runs in the calling thread. PyAV's decoder and encoder, OpenCV and MediaPipe's graph do their
work in C++ with the GIL released, so on two cores the three overlap.

Results do not depend on the threads: every frame is decoded, detected and tracked exactly as in a
serial run, in the same order (the detector sees the same frames in the same order; its video mode
depends on nothing else), so the outputs are bitwise those of ``threads=False``
(``tests/capture/test_capture_pipeline.py``). The queues are bounded (memory stays a few frames).
An error in a background thread is raised again in the calling thread, as the same exception, at
its next exchange with that thread; an error or an interrupt in the calling thread stops the
background threads before it propagates.
"""

from __future__ import annotations

import contextlib
import queue
import sys
import threading
import time
from collections.abc import Callable, Iterator

import numpy as np

#: frames decoded ahead / waiting for the overlay (bounded: memory does not grow with the video)
DEPTH = 4
#: GIL switch interval while the threads run (seconds; CPython's default is 0.005): a background
#: thread that waits for the GIL between two C++ calls waits at most this long for the tracker's
#: Python code to hand it over
SWITCH_INTERVAL = 0.0005

_END = object()


class _Failed:
    """An exception raised in a background thread, carried to the calling thread."""

    def __init__(self, exc: BaseException):
        self.exc = exc


def _put(q: queue.Queue, item, stop: threading.Event) -> bool:
    """Put ``item`` unless ``stop`` is set first; False when stopped."""
    while not stop.is_set():
        try:
            q.put(item, timeout=0.05)
            return True
        except queue.Full:
            continue
    return False


def _drain(q: queue.Queue) -> None:
    with contextlib.suppress(queue.Empty):
        while True:
            q.get_nowait()


class FrameReader:
    """Frames of a source with their detections, produced in a background thread or inline.

    Parameters
    ----------
    frames : iterator of ndarray (H, W, 3) uint8
        The decoded frames (a :meth:`FrameSource.frames` generator).
    detect : callable or None
        ``detect(frame) -> (L, 2) array or None``, run on the frames selected by ``detect_first``
        (frame 0) and ``detect_rest`` (the others); None: no detection.
    secs : dict
        Wall seconds spent decoding and detecting are added to ``secs["decode"]`` / ``secs["detect"]``.
    threaded : bool
        Produce ahead in a background thread (True) or on demand in the caller's thread (False).
    depth : int
        Frames produced ahead at most.

    Iterating yields ``(frame, detection)``; ``detection`` is None where no detection was run or no
    face was found.
    """

    def __init__(self, frames: Iterator[np.ndarray], detect: Callable | None, secs: dict, *,
                 detect_first: bool = True, detect_rest: bool = True, threaded: bool = True, depth: int = DEPTH):
        self._frames, self._detect, self._secs = frames, detect, secs
        self._first, self._rest = detect_first, detect_rest
        self._threaded = threaded
        self._q: queue.Queue = queue.Queue(maxsize=max(1, int(depth)))
        self._stop = threading.Event()
        self._thread = None
        if threaded:
            self._thread = threading.Thread(target=self._run, name="facebasis-capture-reader", daemon=True)
            self._thread.start()
        self._gen = None if threaded else self._produce()

    def _produce(self):
        i = 0
        while True:
            t = time.perf_counter()
            frame = next(self._frames, None)
            self._secs["decode"] += time.perf_counter() - t
            if frame is None:
                return
            d = None
            if self._detect is not None and (self._first if i == 0 else self._rest):
                t = time.perf_counter()
                d = self._detect(frame)
                self._secs["detect"] += time.perf_counter() - t
            yield frame, d
            i += 1

    def _run(self) -> None:
        try:
            for item in self._produce():
                if not _put(self._q, item, self._stop):
                    return
            _put(self._q, _END, self._stop)
        except BaseException as exc:  # noqa: BLE001 - carried to the calling thread and raised there
            _put(self._q, _Failed(exc), self._stop)

    def __iter__(self):
        return self

    def __next__(self):
        if not self._threaded:
            return next(self._gen)
        item = self._q.get()
        if item is _END:
            self._q.put(_END)          # later calls stop too
            raise StopIteration
        if isinstance(item, _Failed):
            self._q.put(item)
            raise item.exc
        return item

    def close(self) -> None:
        """Stop the background thread (it finishes the frame it is on) and wait for it."""
        if self._thread is not None:
            self._stop.set()
            _drain(self._q)
            self._thread.join()
            self._thread = None
        if self._gen is not None:
            self._gen.close()
        close = getattr(self._frames, "close", None)   # a decoder generator closes its container
        if close is not None:
            close()


class OverlayThread:
    """Draw (:func:`~facebasis.capture.overlay.draw_overlay`) and encode overlay frames behind the tracker.

    Parameters
    ----------
    writer : OverlayWriter
    faces : ndarray, shape (M, 3)
    secs : dict
        Wall seconds spent drawing and encoding are added to ``secs["output"]``.
    threaded : bool
        In a background thread (True) or at once in the caller's thread (False).
    depth : int
        Frames waiting at most.
    """

    def __init__(self, writer, faces: np.ndarray, secs: dict, *, threaded: bool = True, depth: int = DEPTH):
        self._writer, self._faces, self._secs = writer, faces, secs
        self._q: queue.Queue = queue.Queue(maxsize=max(1, int(depth)))
        self._stop = threading.Event()
        self._error: BaseException | None = None
        self._thread = None
        if threaded:
            self._thread = threading.Thread(target=self._run, name="facebasis-capture-overlay", daemon=True)
            self._thread.start()

    def _write(self, item) -> None:
        from .overlay import draw_overlay

        t = time.perf_counter()
        frame, vertices, landmarks, lost = item
        self._writer.write(draw_overlay(frame, vertices, self._faces, landmarks, lost))
        self._secs["output"] += time.perf_counter() - t

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                try:
                    item = self._q.get(timeout=0.05)
                except queue.Empty:
                    continue
                if item is _END:
                    return
                self._write(item)
        except BaseException as exc:  # noqa: BLE001 - raised again in the calling thread
            self._error = exc
            self._stop.set()
            _drain(self._q)

    def put(self, frame: np.ndarray, vertices: np.ndarray, landmarks: np.ndarray,
            lost: np.ndarray | None = None) -> None:
        """Queue one frame's overlay (the arrays must not be changed afterwards)."""
        item = (frame, vertices, landmarks, lost)
        if self._thread is None:
            self._write(item)
            return
        if self._error is None:
            _put(self._q, item, self._stop)
        if self._error is not None:
            raise self._error

    def close(self, finish: bool = True) -> None:
        """Write what is queued (``finish``) or drop it, stop the thread and close the video file."""
        try:
            if self._thread is not None:
                if finish:
                    _put(self._q, _END, self._stop)
                else:
                    self._stop.set()
                    _drain(self._q)
                self._thread.join()
                self._thread = None
                if finish and self._error is not None:
                    raise self._error
        finally:
            t = time.perf_counter()
            if self._error is None:
                self._writer.close()
            else:  # the first error is the one to report: closing a writer that failed usually fails too
                with contextlib.suppress(Exception):
                    self._writer.close()
            self._secs["output"] += time.perf_counter() - t


_SETTINGS_LOCK = threading.Lock()
_settings_state = {"depth": 0, "saved": None}  # runs inside thread_settings, and what the first one found


@contextlib.contextmanager
def thread_settings(threaded: bool):
    """While the pipeline runs: OpenCV on one thread (its own worker threads only compete with the
    pipeline's on small frames, and cost CPU time spinning on a loaded machine; results are the same)
    and, with background threads, a shorter GIL switch interval (:data:`SWITCH_INTERVAL`). Both are
    process-wide: they are saved when the first of overlapping runs starts and restored when the last
    one ends (a run that ends first must not restore another run's temporary values)."""
    import cv2

    with _SETTINGS_LOCK:
        if _settings_state["depth"] == 0:
            _settings_state["saved"] = (cv2.getNumThreads(), sys.getswitchinterval())
        _settings_state["depth"] += 1
        cv2.setNumThreads(1)
        if threaded:
            sys.setswitchinterval(min(sys.getswitchinterval(), SWITCH_INTERVAL))
    try:
        yield
    finally:
        with _SETTINGS_LOCK:
            _settings_state["depth"] -= 1
            if _settings_state["depth"] == 0:
                n, interval = _settings_state["saved"]
                cv2.setNumThreads(n)
                sys.setswitchinterval(interval)
