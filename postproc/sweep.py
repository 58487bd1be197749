#!/usr/bin/env python3
"""postproc/sweep.py, the old path of dkt-sweep (dktlbm.sweep)."""

import sys

from dktlbm.sweep import main

if __name__ == "__main__":
    sys.exit(main())
