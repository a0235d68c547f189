"""``python -m dbench.cli``: the ``dbench`` command."""
import sys

from . import main

sys.exit(main())
