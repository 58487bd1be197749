# Benchmark (label perf, not in the default test run): MLUPS of the flow-only 500 x 1250 channel
# with MRT and BGK on 1 and 2 ranks, median of 3 runs each. Run it with `ctest --preset perf`
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
    ENVIRONMENT "OMPI_ALLOW_RUN_AS_ROOT=1;OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1")
endif()
