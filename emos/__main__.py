import sys

from emos.supervisor.cli import main

sys.exit(main())
