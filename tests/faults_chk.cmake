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
# The flow guard's row pass gives the node-by-node scan's largest Mach number bit for bit, and
# hands every slab it does not clear (a NaN, an infinity, a Mach number above the limit, an
# overflowing density) to the scan for the verdict and the message.
dkt_add_fortran_test(NAME test_guard SOURCES dkt_check.f90 test_guard.f90
  LABELS unit NO_MPIEXEC TIMEOUT 30)
# A restart continues the physics it started with (tests/test_faults_physics.py): a changed
# gravity, collision model, bounce-back, viscosity or particle density is refused with the key
# and both values and nothing touched, allowed and recorded through run.restart_changes; run
# length and output keys resume bit for bit; a 2-rank checkpoint resumes on 3 uneven ranks.
# About 10 short jobs on 2 and 3 ranks.
dkt_add_pytest(NAME faults_physics FILE tests/test_faults_physics.py LABELS mpi regression
  PROCESSORS 3 TIMEOUT 600)
# Shared output directories (tests/test_faults_shared.py): a second run into the directory a
# live run of the same scene writes (with output.overwrite, without, or resuming) is refused
# with the holder named and nothing changed; a run killed outright leaves no stale hold.
dkt_add_pytest(NAME faults_shared FILE tests/test_faults_shared.py LABELS mpi regression
  PROCESSORS 2 TIMEOUT 600)
