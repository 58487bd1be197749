# MPI with the Fortran 2008 bindings (mpi_f08) and parallel HDF5 with the Fortran interface.
# Both are required: the solver is an MPI program and writes its fields collectively.

find_package(MPI REQUIRED COMPONENTS Fortran)
if(NOT MPI_Fortran_HAVE_F08_MODULE)
  message(FATAL_ERROR
    "dktlbm needs an MPI library with the Fortran 2008 module 'mpi_f08' for "
    "${CMAKE_Fortran_COMPILER} (found MPI ${MPI_Fortran_VERSION} without it). "
    "On Debian/Ubuntu: apt-get install libopenmpi-dev openmpi-bin; on a cluster, load an MPI "
    "module built with this Fortran compiler.")
endif()

# Which MPI: Debian names its per-MPI HDF5 wrappers after it, and only Open MPI's mpiexec takes
# --oversubscribe. DKT_MPI_FLAVOUR is openmpi, mpich or other.
execute_process(COMMAND "${MPIEXEC_EXECUTABLE}" --version
  OUTPUT_VARIABLE _dkt_mpiexec_version ERROR_VARIABLE _dkt_mpiexec_version
  RESULT_VARIABLE _dkt_mpiexec_status)
if(_dkt_mpiexec_version MATCHES "Open MPI|OpenRTE")
  set(DKT_MPI_FLAVOUR openmpi)
elseif(_dkt_mpiexec_version MATCHES "HYDRA|MPICH")
  set(DKT_MPI_FLAVOUR mpich)
else()
  set(DKT_MPI_FLAVOUR other)
endif()

# The parallel build of HDF5 is the one behind the h5pfc wrapper; ask for it first, so that a
# machine that also has the serial libhdf5-dev (h5fc) still gets the parallel library.
set(HDF5_PREFER_PARALLEL TRUE)
if(NOT DEFINED HDF5_Fortran_COMPILER_EXECUTABLE AND NOT DEFINED HDF5_ROOT
   AND NOT DEFINED ENV{HDF5_ROOT})
  # Debian/Ubuntu keep the per-MPI wrappers under these names (h5pfc is an alternative that
  # may point to another MPI flavour than the one found above).
  if(DKT_MPI_FLAVOUR STREQUAL "other")
    set(_dkt_h5pfc_names h5pfc)
  else()
    set(_dkt_h5pfc_names h5pfc.${DKT_MPI_FLAVOUR} h5pfc)
  endif()
  find_program(DKT_H5PFC NAMES ${_dkt_h5pfc_names} NAMES_PER_DIR
    DOC "HDF5 parallel Fortran compiler wrapper (h5pfc)")
  mark_as_advanced(DKT_H5PFC)
  if(DKT_H5PFC)
    set(HDF5_Fortran_COMPILER_EXECUTABLE "${DKT_H5PFC}" CACHE FILEPATH
      "HDF5 Fortran compiler wrapper")
  endif()
endif()

string(CONCAT _dkt_hdf5_hint "dktlbm needs parallel HDF5 with the Fortran interface; on Debian/Ubuntu: "
  "apt-get install libhdf5-openmpi-dev (or point HDF5_ROOT / "
  "HDF5_Fortran_COMPILER_EXECUTABLE at the h5pfc of a parallel HDF5 build)")
find_package(HDF5 COMPONENTS Fortran)
if(NOT HDF5_FOUND)
  message(FATAL_ERROR "${_dkt_hdf5_hint}")
endif()
if(NOT HDF5_IS_PARALLEL)
  message(FATAL_ERROR "HDF5 ${HDF5_VERSION} found (${HDF5_Fortran_COMPILER_EXECUTABLE} "
    "${HDF5_INCLUDE_DIRS}) is serial. ${_dkt_hdf5_hint}")
endif()
message(STATUS "MPI: ${DKT_MPI_FLAVOUR} (${MPIEXEC_EXECUTABLE}); HDF5 ${HDF5_VERSION}: "
  "HDF5_IS_PARALLEL=${HDF5_IS_PARALLEL}, ${HDF5_Fortran_COMPILER_EXECUTABLE}, "
  "include ${HDF5_INCLUDE_DIRS}")
