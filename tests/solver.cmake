# Tests of the fluid solver: the collision kernel against its matrix form (unit), analytic flows
# through the whole program (regression), and rank-count independence (mpi).
dkt_add_fortran_test(NAME test_mrt SOURCES dkt_check.f90 test_mrt.f90 LABELS unit NO_MPIEXEC)
dkt_add_fortran_test(NAME test_mrt_sp SOURCES dkt_check.f90 test_mrt_sp.f90 LABELS unit NO_MPIEXEC)
# lbm.precision = 'half': the 16-bit format (all 65536 codes, rounding, clamp) and its sweep
dkt_add_fortran_test(NAME test_half SOURCES dkt_check.f90 test_half.f90 LABELS unit NO_MPIEXEC)
dkt_add_pytest(NAME analytic_flows FILE tests/test_flows.py LABELS regression PROCESSORS 2
  TIMEOUT 600)
# lbm.precision: 4-byte storage against the analytic flows, the naive form, the memory count
dkt_add_pytest(NAME precision FILE tests/test_precision.py LABELS regression TIMEOUT 300)
dkt_add_pytest(NAME decomposition_bitwise FILE tests/test_decomposition.py LABELS mpi
  PROCESSORS 3 TIMEOUT 600)
if(DKTLBM_SANITIZE)
  # Sanitized, the particle tests that exercise every particle routine on small lattices (links,
  # contact, refill); owners across slabs are in the matrix; the validations run optimised.
  set(_dkt_particles_args -k "head_on or mass_is_conserved or stiff")
endif()
dkt_add_pytest(NAME particles FILE tests/test_particles.py LABELS regression mpi PROCESSORS 3
  TIMEOUT 1500 ARGS ${_dkt_particles_args})
# coupling.interior = 'fluid': mass to round-off with half-way bounce-back, the settling disk's
# Re_max, restart bit for bit, the models line (seconds); the disk barely denser than the fluid
# settles alike with either interior (2 s of settling, four runs: long)
dkt_add_pytest(NAME interior FILE tests/test_interior.py LABELS regression mpi PROCESSORS 3
  TIMEOUT 600 ARGS -k "not barely_denser")
dkt_add_pytest(NAME interior_density_ratio FILE tests/test_interior.py LABELS regression long
  PROCESSORS 2 TIMEOUT 900 ARGS -k "barely_denser")
# solid interiors reset only when the lattice is read: fields every 7 steps on 2 and 3 ranks and
# a checkpoint off their schedule, resumed on another rank count, against runs that read the
# lattice after every step (the 504-disk box, 36 steps; seconds)
dkt_add_pytest(NAME interior_deferred FILE tests/test_interior_deferred.py LABELS regression mpi
  PROCESSORS 3 TIMEOUT 600)
dkt_add_fortran_test(NAME test_collisions SOURCES dkt_check.f90 test_collisions.f90 LABELS unit NO_MPIEXEC)
# the balanced split of the rows against a search over every split (300 random cost profiles)
dkt_add_fortran_test(NAME test_balance SOURCES dkt_check.f90 test_balance.f90 LABELS unit NO_MPIEXEC)
# the contact partners of a step against every candidate, bit for bit, for disks within the
# drift of their start (40 random crowds of 400 disks, pairs at the reach exactly)
dkt_add_fortran_test(NAME test_collision_partners SOURCES dkt_check.f90 test_collision_partners.f90
  LABELS unit NO_MPIEXEC)
# the link search through the cell list against a search over every disk, on 1 rank and across
# an uneven split of 3 ranks (90 rows)
dkt_add_fortran_test(NAME test_cells SOURCES dkt_check.f90 test_cells.f90 LABELS unit)
dkt_add_fortran_test(NAME test_cells_3ranks SOURCES dkt_check.f90 test_cells.f90 LABELS unit mpi
  RANKS 3)
if(DKTLBM_SANITIZE)
  # Sanitized ranks are a few times slower, and more ranks than cores (3 or 4 on CI's 2) wait
  # on each other some 25 times longer: the matrix runs its small cases on 1 and 2 ranks (the
  # uneven splits of 2 ranks are where the window shift overran); 3 and 4 ranks and the
  # paper-resolution repro run in the optimised build, and so does the comparison of two lattices
  # with in place (the same sweep code; the sanitized matrix runs in place).
  set(_dkt_matrix_args -k "not repro and not -3] and not -4] and not two_lattices and not window_uneven_rows_3_fluid")
else()
  # the window case with interior fluid (six runs, 11 s) is a long check of its own
  set(_dkt_matrix_args -k "not window_uneven_rows_3_fluid")
  dkt_add_pytest(NAME rank_matrix_window_fluid FILE tests/test_rank_matrix.py LABELS mpi long
    PROCESSORS 4 TIMEOUT 900 ARGS -k "window_uneven_rows_3_fluid")
endif()
dkt_add_pytest(NAME rank_matrix FILE tests/test_rank_matrix.py LABELS mpi PROCESSORS 4
  TIMEOUT 1200 ARGS ${_dkt_matrix_args})
# The gamma sweep: which splits it meets, against the matrix (seconds, every run), and all 21
# points at paper resolution on 2 ranks against 1 (minutes: `ctest --preset long`)
dkt_add_pytest(NAME sweep_splits FILE tests/test_sweep_ranks.py LABELS mpi
  ARGS -k "matrix_covers")
dkt_add_pytest(NAME sweep_ranks FILE tests/test_sweep_ranks.py LABELS mpi long PROCESSORS 2
  TIMEOUT 1500 ARGS -k "bitwise")
# Particles owned by slabs: a box of settling disks on 1-4 ranks and both transports, migration
# across every slab face, a restart on another rank count, the messages per step
dkt_add_pytest(NAME particle_slabs FILE tests/test_particle_slabs.py LABELS mpi PROCESSORS 4
  TIMEOUT 900)
# Slabs that follow the load: borders moved at the first step give the bits of one rank and of
# fixed slabs on 2-4 ranks (TCP too), and a restart after a move on another rank count
dkt_add_pytest(NAME balance FILE tests/test_balance.py LABELS mpi PROCESSORS 4 TIMEOUT 900)
