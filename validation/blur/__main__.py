"""``python -m validation.blur -o OUT [--quick]`` (the same as ``exposim validate blur``)."""

import sys

from validation.blur.cli import main

if __name__ == "__main__":
    sys.exit(main())
