# The Slurm batch scripts in input/slurm/ (one run, and a sweep's job array): run under bash
# with stand-ins for srun, sbatch, scontrol and dktlbm, they finish, fail, or stop with a
# checkpoint and resubmit themselves with --restart, within MAX_RESUBMITS.
dkt_add_pytest(NAME slurm_scripts FILE tests/test_slurm_scripts.py LABELS unit)
