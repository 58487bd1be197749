"""`import dktread` gives dktlbm.read (the run-file reader), for code written before the
package."""

import sys

import dktlbm.read

sys.modules[__name__] = dktlbm.read
