# Checkpoints that cannot lie (tests/test_faults_chk.py): damaged and altered checkpoints (a
# flipped byte, float32 populations, NaN and Inf, particles out of place, too fast or
# overlapping, a wrong window shift, step or sample count) are refused within a timeout with
# one message and nothing of the run changed; a finished run extended from its last checkpoint
# repeats no sample. About 20 short jobs on 2 ranks.
dkt_add_pytest(NAME faults_checkpoint FILE tests/test_faults_chk.py LABELS mpi regression
  PROCESSORS 2 TIMEOUT 600)
# The window's follow loop is bounded: NaN, -Infinity and absurd positions return (a hang here
# fails by the timeout).
dkt_add_fortran_test(NAME test_window_follow SOURCES dkt_check.f90 test_window_follow.f90
  LABELS unit NO_MPIEXEC TIMEOUT 30)
