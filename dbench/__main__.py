"""``python -m dbench``: the ``dbench`` command (dbench.cli)."""
import sys

from .cli import main

sys.exit(main())
