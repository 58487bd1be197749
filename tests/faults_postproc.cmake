# Postprocessing on broken, running, paused and killed runs (tests/test_faults_postproc.py): a
# documented status (run_status, sweep collect) or one error line from dkt-pattern and dkt-gap,
# no hang, no stale pattern after a killed extension of a finished run, a sweep that leaves a
# live run alone, and a warning for a NaN gap. A few short jobs on 2 ranks.
dkt_add_pytest(NAME faults_postproc FILE tests/test_faults_postproc.py LABELS mpi regression
  PROCESSORS 2 TIMEOUT 600)
