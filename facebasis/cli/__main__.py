"""``python -m facebasis.cli``: the same as the ``facebasis`` command."""

import sys

from . import main

sys.exit(main())
