"""``python -m validation.live -o OUT [--quick] ...`` (the same as ``exposim validate live``)."""

import sys

from validation.live.cli import main

if __name__ == "__main__":
    sys.exit(main())
