"""``python -m validation.emulation``."""

import sys

from validation.emulation.cli import main

sys.exit(main())
