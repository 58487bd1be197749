"""dktlbm post-processing: read dktlbm run files, plot and classify them, run sweeps.

Modules: read (the run-file reader), launch (starting dktlbm on MPI ranks), gap,
trajectories, drag, field, pattern, sweep (each also a console command dkt-<name>).
postproc/README.md documents them.
"""
