"""``python -m validation.render_study``."""

import sys

from validation.render_study.cli import main

sys.exit(main())
