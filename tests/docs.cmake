# The README and the pages beside it: at most 300 lines, every link resolves, every command of
# its ```sh blocks checked (runs with --check, tools with --help and, when cheap, for real on a
# small run), its h5py example and scene run, one version in CMakeLists.txt, CHANGELOG.md,
# CITATION.cff and pyproject.toml. About 30 s; one command uses 2 ranks.
dkt_add_pytest(NAME docs_readme FILE tests/test_readme.py LABELS postproc PROCESSORS 2
  TIMEOUT 300)
