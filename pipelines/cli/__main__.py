"""``python -m pipelines.cli ...``: the ``humancal`` command without its installed script."""

import sys

from pipelines.cli import main

sys.exit(main())
