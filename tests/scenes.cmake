# Tests of the DKT scenes: the pair diagnostics (unit), the moving window of the infinite channel
# against a tall static channel, its rank-count independence and its bookkeeping, and the DKT
# pattern report of a window run (regression, mpi).
dkt_add_fortran_test(NAME test_diagnostics SOURCES dkt_check.f90 test_diagnostics.f90
  LABELS unit NO_MPIEXEC)
dkt_add_pytest(NAME window FILE tests/test_window.py LABELS regression mpi PROCESSORS 3
  TIMEOUT 900)
# Checkpoint and restart (issue: a cluster run survives its wall-clock limit and resumes bit for bit)
dkt_add_pytest(NAME restart FILE tests/test_restart.py LABELS regression mpi PROCESSORS 3
  TIMEOUT 900)
