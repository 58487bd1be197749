# Validation of the DKT scenes against published values (docs/model.md §8), at the paper's
# resolution.
dkt_add_pytest(NAME dkt_validation FILE tests/test_dkt_validation.py LABELS regression mpi
  PROCESSORS 2 TIMEOUT 900)
