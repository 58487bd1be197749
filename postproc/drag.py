#!/usr/bin/env python3
"""postproc/drag.py, the old path of dkt-drag (dktlbm.drag), kept for scripts written before the
package only: use `dkt-drag`, or `python3 -m dktlbm.drag` with the package installed or on
PYTHONPATH (postproc/README.md)."""

import sys

from dktlbm.drag import main

if __name__ == "__main__":
    sys.exit(main())
