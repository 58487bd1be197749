# Tests of the program as a user meets it: bad input on the command line and in scene files
# (clear message, non-zero exit, no hang, no output), the run-time guards (Mach number,
# non-finite values), and the output contract of a real run (HDF5 layout, /run attributes,
# physical fields, XDMF sidecar, log copy).
#
# test_bad_input.py runs one case on 4 ranks (more ranks than the scene's rows allow); it stops
# during set-up, so the file's real load is 2 ranks.
dkt_add_pytest(NAME cli_bad_input FILE tests/test_bad_input.py LABELS mpi PROCESSORS 2
  TIMEOUT 180)
# test_input_fuzz.py: about 90 classes of bad input and seeded mutations of every scene of
# input/, each refused cleanly (exit 2, one message, no output) or accepted by --check; some 140
# short jobs on 2 ranks, about 60 s on 2 busy cores.
dkt_add_pytest(NAME cli_input_fuzz FILE tests/test_input_fuzz.py LABELS mpi PROCESSORS 2
  TIMEOUT 300)
dkt_add_pytest(NAME cli_guards FILE tests/test_guards.py LABELS mpi PROCESSORS 2 TIMEOUT 120)
# test_stability.py: preview runs at the extremes (tau, density ratio, particle Reynolds number,
# gamma, wall and contact approaches), each stable with a stated bound, stopped by a named guard,
# or refused (docs/stability.md). The cheap cases (about 25 s on 2 busy cores) run by default;
# stability_extremes adds the rest (about 60 s) and runs only with `ctest -L stability`.
dkt_add_pytest(NAME stability FILE tests/test_stability.py LABELS mpi stability PROCESSORS 2
  TIMEOUT 180)
dkt_add_pytest(NAME stability_extremes FILE tests/test_stability.py LABELS stability long
  PROCESSORS 2 TIMEOUT 600 ENV "DKTLBM_STABILITY=all")
dkt_add_pytest(NAME cli_output_contract FILE tests/test_output_contract.py LABELS regression
  PROCESSORS 2 TIMEOUT 120)
# A run that stops early (guard, signal, wall limit, failed marker write) keeps its output up to
# the stop with /run stop_reason; damaged checkpoints are refused; postproc says why a run
# ended early. Runs of a few seconds each on 2 ranks.
dkt_add_pytest(NAME restart_stops FILE tests/test_stops.py LABELS mpi regression PROCESSORS 2
  TIMEOUT 600)
# test_contact_stability.py: light disks held at contact with walls and with each other for 10^5
# steps (a disk on the floor, in a corner, a pile of three) at 8 and 16 per D, contact range 1 to
# 3 spacings and 0.5 with lubrication, Yu's bounce-back and halfway and BFL, on 1 and 2 ranks
# (uneven slabs, bitwise the same): no guard stop, no overlap, at rest within the contact range
# (docs/stability.md, "Disks at contact"). About 5 min on 2 cores.
dkt_add_pytest(NAME stability_contact FILE tests/test_contact_stability.py LABELS mpi stability
  PROCESSORS 2 TIMEOUT 1500)
# test_lubrication.py: a light disk draining the film to the floor and to a fixed disk at 8 per D
# follows the 2-D lubrication theory within 25 % at gaps of 0.1-0.3 spacings with E13, misses it
# by more than 2x without, and gives the same bits on 2 ranks (docs/model.md §4). About 10 s.
dkt_add_pytest(NAME lubrication FILE tests/test_lubrication.py LABELS mpi stability PROCESSORS 2
  TIMEOUT 300)
