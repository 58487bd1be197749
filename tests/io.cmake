# dkt_io: parallel HDF5 fields, /run metadata, time series and the XDMF sidecar.
# test_io_prog writes the files on 1-4 ranks (uneven slabs, one rank without rows);
# test_io_readback.py runs it and reads them back with h5py.
add_executable(test_io_prog "${CMAKE_CURRENT_LIST_DIR}/test_io.f90")
target_link_libraries(test_io_prog PRIVATE dktlbm_core)
set_target_properties(test_io_prog PROPERTIES
  RUNTIME_OUTPUT_DIRECTORY "${CMAKE_CURRENT_BINARY_DIR}"
  Fortran_MODULE_DIRECTORY "${CMAKE_BINARY_DIR}/mod/tests/test_io_prog")
dkt_set_fortran_flags(test_io_prog)
dkt_add_pytest(NAME io_readback FILE tests/test_io_readback.py LABELS mpi PROCESSORS 4
  ENV "DKT_TEST_IO_EXE=$<TARGET_FILE:test_io_prog>")

# The run file as ParaView reads it (pvpython with the XDMF reader): the main job's lattice.
dkt_add_pytest(NAME paraview FILE tests/test_paraview.py LABELS paraview mpi PROCESSORS 2
  TIMEOUT 900)

# Ten thousand disks as ParaView draws them: the particle grid with each disk's radius, glyphs
# scaled by it.
dkt_add_pytest(NAME paraview_disks FILE tests/test_paraview_disks.py LABELS paraview mpi
  PROCESSORS 2 TIMEOUT 900)

# The disks as a user draws them in ParaView: the particle sidecar, one Glyph made once, the
# time stepped through, after a restart; the sidecar's place among the files of a run.
dkt_add_pytest(NAME paraview_particles FILE tests/test_paraview_particles.py LABELS paraview mpi
  PROCESSORS 2 TIMEOUT 600)
