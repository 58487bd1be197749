#!/usr/bin/env python3
"""postproc/trajectories.py, the old path of dkt-trajectories (dktlbm.trajectories)."""

import sys

from dktlbm.trajectories import main

if __name__ == "__main__":
    sys.exit(main())
