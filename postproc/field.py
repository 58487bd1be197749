#!/usr/bin/env python3
"""postproc/field.py, the old path of dkt-field (dktlbm.field)."""

import sys

from dktlbm.field import main

if __name__ == "__main__":
    sys.exit(main())
