"""``python -m validation.calibration_study``."""

import sys

from validation.calibration_study.cli import main

sys.exit(main())
