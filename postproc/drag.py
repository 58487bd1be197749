#!/usr/bin/env python3
"""postproc/drag.py, the old path of dkt-drag (dktlbm.drag)."""

import sys

from dktlbm.drag import main

if __name__ == "__main__":
    sys.exit(main())
