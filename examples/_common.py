"""Where an example writes: ``$FACEBASIS_EXAMPLES_OUT/<script>/`` (default ``./example_output/<script>/``)."""

import os
from pathlib import Path


def output_folder(script: str) -> Path:
    root = Path(os.environ.get("FACEBASIS_EXAMPLES_OUT", "example_output"))
    out = root / Path(script).stem
    out.mkdir(parents=True, exist_ok=True)
    return out
