# The Slurm batch scripts in input/slurm/ (one run, and a sweep's job array): run under bash
# with stand-ins for srun, sbatch, scontrol and dktlbm, they finish, fail, or stop with a
# checkpoint and resubmit themselves with --restart, within MAX_RESUBMITS.
dkt_add_pytest(NAME slurm_scripts FILE tests/test_slurm_scripts.py LABELS unit)
# The same scripts and `dkt-sweep slurm` against a real Slurm (tools/slurm-local.sh start): a
# chain cut by SIGUSR1 equal to a direct run, a sweep task interrupted and resumed, a sweep
# collected into a regime map, and a sweep written and submitted by an installed copy.
# Skipped (in seconds) when `sinfo` reaches no Slurm.
dkt_add_pytest(NAME slurm_real FILE tests/test_slurm_real.py LABELS slurm_real TIMEOUT 1200
               PROCESSORS 2 ENV "DKT_BUILD_DIR=${CMAKE_BINARY_DIR}" "DKT_CMAKE=${CMAKE_COMMAND}")
