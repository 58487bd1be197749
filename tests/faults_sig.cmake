# test_faults_sig.py: every stopping signal (SIGINT, SIGHUP, SIGTERM, SIGUSR1/2, SIGXCPU,
# SIGALRM) at seeded random moments, to a plain run and to mpirun -n 2, checkpoints, says
# stop_reason 'signal' with the documented exit status and resumes bitwise equal to a run that
# never stopped; a signal before the first step is held; `| head` does not stop a run.
dkt_add_pytest(NAME faults_sig FILE tests/test_faults_sig.py LABELS mpi regression PROCESSORS 2
  TIMEOUT 900)
