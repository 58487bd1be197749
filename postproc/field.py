#!/usr/bin/env python3
"""postproc/field.py, the old path of dkt-field (dktlbm.field), kept for scripts written before
the package only: use `dkt-field`, or `python3 -m dktlbm.field` with the package installed or on
PYTHONPATH (postproc/README.md)."""

import sys

from dktlbm.field import main

if __name__ == "__main__":
    sys.exit(main())
