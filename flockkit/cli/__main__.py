"""``python -m flockkit.cli``: the ``flockkit`` command."""

import sys

from . import main

sys.exit(main())
