# Post-processing (postproc/, Python): the run-file reader and DKT classifier, pattern.py, the
# plotting scripts' command lines and bad-input handling (synthetic run files and two small
# real runs, the larger on 2 ranks), and the sweep tool (plan, Slurm array, collect, one real
# run through `dkt-sweep run`), and the threshold search `dkt-sweep bisect` (a stand-in program,
# here and through Slurm stand-ins, plus one real bisection of ten coarse runs, under a minute).
dkt_add_pytest(NAME postproc FILE tests/postproc/test_postproc.py LABELS postproc PROCESSORS 2
  TIMEOUT 600)
# The reader on the old and the new form of the run file, and the values it takes for files
# without stored scales against what the executable reports (--print-defaults, --check).
dkt_add_pytest(NAME postproc_read FILE tests/postproc/test_read.py LABELS postproc)
# Run.to_dataframe() and Run.to_xarray(): the series with their units (pandas and xarray
# parts skipped where they are not installed: pip install 'dktlbm[frames]').
dkt_add_pytest(NAME postproc_frames FILE tests/postproc/test_frames.py LABELS postproc)
# dkt-field --movie: a frame per stored snapshot, MP4 (ffprobe) or GIF without ffmpeg.
dkt_add_pytest(NAME postproc_movie FILE tests/postproc/test_movie.py LABELS postproc)
dkt_add_pytest(NAME postproc_sweep FILE tests/postproc/test_sweep.py LABELS postproc
  TIMEOUT 300)
dkt_add_pytest(NAME postproc_bisect FILE tests/postproc/test_bisect.py LABELS postproc
  PROCESSORS 2 TIMEOUT 300)
# `dkt-sweep map`: the borders between patterns across gamma and dh, against a stand-in program
# with two known straight borders (in-process, and once through the command line).
dkt_add_pytest(NAME postproc_map FILE tests/postproc/test_map.py LABELS postproc
  PROCESSORS 2 TIMEOUT 300)
# dkt-paraview: one error line without pvpython or a display; with ParaView, the PNG of a small
# real run with the disks of its particle sidecar.
dkt_add_pytest(NAME postproc_paraview FILE tests/postproc/test_paraview_command.py
  LABELS postproc paraview)
# The install as a new user meets it: `cmake --install` into a scratch prefix, the package
# pip-installed into a scratch venv, and from an empty directory with only their bin
# directories on PATH an example scene on 2 ranks, dkt-gap, dkt-pattern and dkt-paraview.
dkt_add_pytest(NAME install FILE tests/test_install.py LABELS postproc PROCESSORS 2 TIMEOUT 600
  ENV "DKT_BUILD_DIR=${CMAKE_BINARY_DIR}" "DKT_CMAKE=${CMAKE_COMMAND}")
# Both render through xvfb-run when there is no display; Xvfb servers started at the same moment
# on a loaded machine can refuse pvpython's connection (dkt-paraview tries again, up to three
# times), so the two never run at once.
set_tests_properties(postproc_paraview install PROPERTIES RESOURCE_LOCK xvfb)
