#!/usr/bin/env python3
"""postproc/gap.py, the old path of dkt-gap (dktlbm.gap), kept for scripts written before the
package only: use `dkt-gap`, or `python3 -m dktlbm.gap` with the package installed or on
PYTHONPATH (postproc/README.md)."""

import sys

from dktlbm.gap import main

if __name__ == "__main__":
    sys.exit(main())
