#!/usr/bin/env python3
"""postproc/gap.py, the old path of dkt-gap (dktlbm.gap)."""

import sys

from dktlbm.gap import main

if __name__ == "__main__":
    sys.exit(main())
