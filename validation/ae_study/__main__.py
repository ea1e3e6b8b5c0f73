"""``python -m validation.ae_study``."""

import sys

from validation.ae_study.cli import main

sys.exit(main())
