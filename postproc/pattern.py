#!/usr/bin/env python3
"""postproc/pattern.py, the old path of dkt-pattern (dktlbm.pattern)."""

import sys

from dktlbm.pattern import main

if __name__ == "__main__":
    sys.exit(main())
