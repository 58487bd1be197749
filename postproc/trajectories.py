#!/usr/bin/env python3
"""postproc/trajectories.py, the old path of dkt-trajectories (dktlbm.trajectories), kept for
scripts written before the package only: use `dkt-trajectories`, or `python3 -m
dktlbm.trajectories` with the package installed or on PYTHONPATH (postproc/README.md)."""

import sys

from dktlbm.trajectories import main

if __name__ == "__main__":
    sys.exit(main())
