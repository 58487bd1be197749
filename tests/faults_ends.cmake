# test_faults_ends.py: a disk meets every end as documented: it comes to rest on an end at rest
# (E11, bitwise equal on 1 and 2 ranks) and stops the run with a 'particle:' reason, its series
# complete, at an open or moving end. Four small boxes of a few hundred steps (seconds).
dkt_add_pytest(NAME faults_ends FILE tests/test_faults_ends.py LABELS mpi regression PROCESSORS 2
  TIMEOUT 300)
