"""``python -m validation.native_loo SEQ -o OUT`` (the same as ``exposim validate native``)."""

import sys

from validation.native_loo.cli import main

if __name__ == "__main__":
    sys.exit(main())
