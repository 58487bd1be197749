# Tests of the fluid solver: the collision kernel against its matrix form (unit), analytic flows
# through the whole program (regression), and rank-count independence (mpi).
dkt_add_fortran_test(NAME test_mrt SOURCES dkt_check.f90 test_mrt.f90 LABELS unit NO_MPIEXEC)
dkt_add_pytest(NAME analytic_flows FILE tests/test_flows.py LABELS regression PROCESSORS 2
  TIMEOUT 600)
dkt_add_pytest(NAME decomposition_bitwise FILE tests/test_decomposition.py LABELS mpi
  PROCESSORS 3 TIMEOUT 600)
dkt_add_pytest(NAME particles FILE tests/test_particles.py LABELS regression mpi PROCESSORS 3
  TIMEOUT 1500)
dkt_add_fortran_test(NAME test_collisions SOURCES dkt_check.f90 test_collisions.f90 LABELS unit NO_MPIEXEC)
