# Benchmark (label perf, not in the default test run): MLUPS of the flow-only 500 x 1250 channel
# with MRT and BGK on 1 and 2 ranks in every storage layout the executable accepts, median of 3
# interleaved runs each, ratios to double/two_lattice, and the memory per cell of each layout.
# Run it with `ctest --preset perf`
# (or `ctest --test-dir build -L perf -V` to see the table).
if(Python3_FOUND)
  add_test(NAME perf_mlups_channel
    COMMAND "${Python3_EXECUTABLE}" "${CMAKE_CURRENT_SOURCE_DIR}/perf/bench_mlups.py"
      --exe $<TARGET_FILE:dktlbm>
      --scene "${PROJECT_SOURCE_DIR}/input/bench_channel.nml"
      --mpiexec "${MPIEXEC_EXECUTABLE}"
      --ranks 1 2 --collisions mrt bgk --repeats 3)
  set_tests_properties(perf_mlups_channel PROPERTIES
    LABELS perf
    TIMEOUT 3600
    RUN_SERIAL TRUE
    # Not the test environment: that one allows oversubscription, which Open MPI answers by not
    # binding ranks to cores.
    ENVIRONMENT "OMPI_ALLOW_RUN_AS_ROOT=1;OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1;PYTHONPATH=${PROJECT_SOURCE_DIR}/postproc")
endif()

# STREAM-like memory bandwidth of the machine (tests/perf/stream_copy.f90), the ceiling of the
# memory-bound sweep: tests/perf/roofline.py runs it on 1 and 2 ranks and prints the MLUPS each
# storage layout could reach at that bandwidth. One small file without dktlbm_core, built with
# the rest so that it stays compiling (debug and asan builds included).
add_executable(stream_copy "${CMAKE_CURRENT_SOURCE_DIR}/perf/stream_copy.f90")
target_link_libraries(stream_copy PRIVATE MPI::MPI_Fortran)
set_target_properties(stream_copy PROPERTIES
  RUNTIME_OUTPUT_DIRECTORY "${CMAKE_CURRENT_BINARY_DIR}"
  Fortran_MODULE_DIRECTORY "${CMAKE_BINARY_DIR}/mod/tests/stream_copy")
dkt_set_fortran_flags(stream_copy)
if(CMAKE_Fortran_COMPILER_ID STREQUAL "GNU")
  # gfortran turns the copy loop into a memcpy call, whose large-size path uses non-temporal
  # stores; the sweep's stores are plain ones, so the copy must be too.
  set_source_files_properties("${CMAKE_CURRENT_SOURCE_DIR}/perf/stream_copy.f90" PROPERTIES
    COMPILE_OPTIONS "-fno-tree-loop-distribute-patterns")
endif()
if(Python3_FOUND)
  add_test(NAME perf_roofline
    COMMAND "${Python3_EXECUTABLE}" "${CMAKE_CURRENT_SOURCE_DIR}/perf/roofline.py"
      --exe $<TARGET_FILE:stream_copy>
      --mpiexec "${MPIEXEC_EXECUTABLE}"
      --ranks 1 2)
  set_tests_properties(perf_roofline PROPERTIES
    LABELS perf
    TIMEOUT 600
    RUN_SERIAL TRUE
    ENVIRONMENT "OMPI_ALLOW_RUN_AS_ROOT=1;OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1;PYTHONPATH=${PROJECT_SOURCE_DIR}/postproc")
endif()

# Particle cost per step (tests/perf/bench_particles.f90): the contact forces and the boundary-
# link search of a crowd of disks, timed apart, median of 5. Built with the rest so that it
# stays compiling; run it by hand, e.g. `build/tests/bench_particles 1000 10000` (docs/performance.md).
add_executable(bench_particles "${CMAKE_CURRENT_SOURCE_DIR}/perf/bench_particles.f90")
target_link_libraries(bench_particles PRIVATE dktlbm_core)
set_target_properties(bench_particles PROPERTIES
  RUNTIME_OUTPUT_DIRECTORY "${CMAKE_CURRENT_BINARY_DIR}"
  Fortran_MODULE_DIRECTORY "${CMAKE_BINARY_DIR}/mod/tests/bench_particles")
dkt_set_fortran_flags(bench_particles)

# Benchmark (label perf): the 504-disk cavity at 8 per D against the same box without disks, on
# 1 and 2 ranks, median of 3 interleaved runs; prints the ratio and what 2 ranks gain for each.
if(Python3_FOUND)
  add_test(NAME perf_suspension
    COMMAND "${Python3_EXECUTABLE}" "${CMAKE_CURRENT_SOURCE_DIR}/perf/bench_suspension.py"
      --exe $<TARGET_FILE:dktlbm> --mpiexec "${MPIEXEC_EXECUTABLE}" --ranks 1 2 --repeats 3)
  set_tests_properties(perf_suspension PROPERTIES
    LABELS perf
    TIMEOUT 3600
    RUN_SERIAL TRUE
    ENVIRONMENT "OMPI_ALLOW_RUN_AS_ROOT=1;OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1")
endif()

# Benchmark (label perf): the cost model of a particle step (per cell, link, interior node and
# particle sub-step) fitted on 1-rank runs of six scenes from 2 to 10 032 disks, checked on 2.
if(Python3_FOUND)
  add_test(NAME perf_cost_model
    COMMAND "${Python3_EXECUTABLE}" "${CMAKE_CURRENT_SOURCE_DIR}/perf/cost_model.py"
      --exe $<TARGET_FILE:dktlbm> --mpiexec "${MPIEXEC_EXECUTABLE}" --check-ranks 2 --repeats 3)
  set_tests_properties(perf_cost_model PROPERTIES
    LABELS perf
    TIMEOUT 3600
    RUN_SERIAL TRUE
    ENVIRONMENT "OMPI_ALLOW_RUN_AS_ROOT=1;OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1")
endif()

# dktlbm's flow step beside lbmpy's generated kernel on the same lattice and core
# (tests/perf/peers.py, docs/performance.md "Side by side with lbmpy"); skipped where lbmpy is not
# installed (pip install lbmpy==1.4.1).
if(Python3_FOUND)
  add_test(NAME perf_peers
    COMMAND "${Python3_EXECUTABLE}" "${CMAKE_CURRENT_SOURCE_DIR}/perf/peers.py"
      --exe $<TARGET_FILE:dktlbm>
      --mpiexec "${MPIEXEC_EXECUTABLE}"
      --repeats 3)
  set_tests_properties(perf_peers PROPERTIES
    LABELS perf
    TIMEOUT 1800
    RUN_SERIAL TRUE
    SKIP_RETURN_CODE 77
    ENVIRONMENT "OMPI_ALLOW_RUN_AS_ROOT=1;OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1;PYTHONPATH=${PROJECT_SOURCE_DIR}/postproc")
endif()
