import sys

from agents.curves.cli import main

sys.exit(main())
