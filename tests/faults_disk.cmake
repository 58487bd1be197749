# A full disk (tests/test_faults_disk.py, root only: a small tmpfs is mounted): a checkpoint that
# does not fit stops the run within a timeout with one message naming it, no partial file, the
# run file closed with its series and the previous checkpoint resumable; a full disk during field
# output names the run file. Two short jobs on 2 ranks.
dkt_add_pytest(NAME faults_disk FILE tests/test_faults_disk.py LABELS mpi regression
  PROCESSORS 2 TIMEOUT 600)
