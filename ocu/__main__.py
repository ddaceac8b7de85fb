"""`python -m ocu` runs the console."""

import sys

from ocu.app import main

sys.exit(main())
