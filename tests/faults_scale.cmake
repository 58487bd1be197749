# Scale in input and output, and --check refuses what the run refuses: 10 000 disks through
# --check and two steps, 700 disks writing their run file, 10^5 disks validated, a 1 MB string
# value, output.dir a file / read-only / too long for MPI-IO, sub-step counts out of range.
# About 60 s on 2 busy cores, most of it --check and the two steps of 10 000 disks.
dkt_add_pytest(NAME faults_scale FILE tests/test_faults_scale.py LABELS mpi PROCESSORS 2
  TIMEOUT 900)
