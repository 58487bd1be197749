# Tests of the input: module dkt_config (namelist parsing, defaults, overrides, validation,
# lattice units, command line) and the agreement of input/README.md with the key registry.
dkt_add_fortran_test(NAME test_config SOURCES test_config.f90 LABELS unit NO_MPIEXEC)
dkt_add_pytest(NAME test_input_readme FILE tests/test_input_readme.py LABELS unit)
# The compiler's read(nml=) against the program's reader, on the files of tests/namelist/.
dkt_add_fortran_test(NAME test_namelist_compiler SOURCES dkt_check.f90 test_namelist_compiler.f90 LABELS unit
  NO_MPIEXEC ARGS ${PROJECT_SOURCE_DIR}/tests/namelist)
# lbm.mach (tau from a target Mach number, acoustic scaling) and the compressibility class of
# the start-up report, through --check on one rank.
dkt_add_pytest(NAME config_mach FILE tests/test_mach.py LABELS unit)
