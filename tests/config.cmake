# Tests of the input: module dkt_config (namelist parsing, defaults, overrides, validation,
# lattice units, command line) and the agreement of input/README.md with the key registry.
dkt_add_fortran_test(NAME test_config SOURCES test_config.f90 LABELS unit NO_MPIEXEC)
dkt_add_pytest(NAME test_input_readme FILE tests/test_input_readme.py LABELS unit)
