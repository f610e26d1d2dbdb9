import sys

from emos.tools.cli import main

sys.exit(main())
