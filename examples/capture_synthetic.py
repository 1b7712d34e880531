"""Markerless capture (Wu & Ju 2016) on a generated video whose true landmarks are known.

:func:`facebasis.capture.synthetic_sequence` draws a cartoon face that talks, blinks and moves its
head; :class:`facebasis.capture.FaceTracker` is built once on the first frame (mesh, factorisation,
particle filter) and tracks the others. The figure shows the landmark error per frame.
"""

import numpy as np

from _common import output_folder
from facebasis.capture import FaceTracker, synthetic_sequence
from facebasis.report.figures import COLUMN, _pyplot, save

out = output_folder(__file__)
seq = synthetic_sequence(30)                                  # frames + exact landmarks (T, 68, 2)
tracker = FaceTracker(seq.frames[0], seq.landmarks[0])
tracked = np.stack([seq.landmarks[0]] + [tracker.track(f).landmarks for f in seq.frames[1:]])
err = np.linalg.norm(tracked - seq.landmarks, axis=2)         # (T, 68) pixels
print(f"{len(seq.frames)} frames: mean landmark error {err.mean():.2f} px, worst {err.max():.2f} px")

plt = _pyplot()
fig, ax = plt.subplots(figsize=(COLUMN, 2.2))
ax.plot(err.mean(1), label="mean over 68 landmarks")
ax.plot(err.max(1), "--", label="worst landmark")
ax.set_xlabel("frame (count)")
ax.set_ylabel("error (px)")
ax.legend(loc="upper left", frameon=False)
save(fig, out / "landmark_error", ("png",))
print(f"figure: {out / 'landmark_error.png'}")
