# Tests of the DKT scenes: the pair diagnostics (unit), the moving window of the infinite channel
# against a tall static channel, its rank-count independence and its bookkeeping, and the DKT
# pattern report of a window run (regression, mpi).
dkt_add_fortran_test(NAME test_diagnostics SOURCES dkt_check.f90 test_diagnostics.f90
  LABELS unit NO_MPIEXEC)
# The disk through three window lengths against a 28 cm static channel (18 s of settling, about
# 100 s on 2 cores) is a long check of its own; every run has the 6-s comparison, which already
# drops every row of the first window.
dkt_add_pytest(NAME window FILE tests/test_window.py LABELS regression mpi PROCESSORS 3
  TIMEOUT 900 ARGS -k "not three_window_lengths")
dkt_add_pytest(NAME window_three_lengths FILE tests/test_window.py LABELS regression long
  PROCESSORS 2 TIMEOUT 900 ARGS -k "three_window_lengths")
# Checkpoint and restart (issue: a cluster run survives its wall-clock limit and resumes bit for bit)
dkt_add_pytest(NAME restart FILE tests/test_restart.py LABELS regression mpi PROCESSORS 3
  TIMEOUT 900)
# A window that grows instead of losing a particle (window.max_above): bitwise on 1-4 ranks and
# two lattices, restarts before and after the growth, the run file's rows, the growth limit
dkt_add_pytest(NAME window_grow FILE tests/test_window_grow.py LABELS regression mpi PROCESSORS 4
  TIMEOUT 900)
