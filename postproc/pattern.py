#!/usr/bin/env python3
"""postproc/pattern.py, the old path of dkt-pattern (dktlbm.pattern), kept for scripts written
before the package only: use `dkt-pattern`, or `python3 -m dktlbm.pattern` with the package
installed or on PYTHONPATH (postproc/README.md)."""

import sys

from dktlbm.pattern import main

if __name__ == "__main__":
    sys.exit(main())
