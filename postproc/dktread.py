"""`import dktread` gives dktlbm.read (the run-file reader), kept for code written before the
package only: use `from dktlbm import read` (postproc/README.md)."""

import sys

import dktlbm.read

sys.modules[__name__] = dktlbm.read
