"""``python -m emos.tools.cli``: the ``emos`` command (systemd units and tests start it this way)."""
import sys

from emos.tools.cli import main

sys.exit(main())
