# Compiler flags of the two build types. They are set on dktlbm's own targets (not in
# CMAKE_Fortran_FLAGS_<CONFIG>) so that what is compiled and what the program reports in
# dkt_build_flags are the same list: DKT_FORTRAN_FLAGS.
#
#   Release: -O3 (+ -march=native when DKTLBM_NATIVE is ON)
#   Debug:   -g -O0, all warnings, run-time checks (all but the array-temporary notes), traps on
#            invalid/zero/overflow, backtraces; with DKTLBM_WERROR (CI) warnings are errors
#   DKTLBM_SANITIZE=address (any build type; the `asan` preset uses Debug): AddressSanitizer on
#            every dktlbm target, compiled and linked, so an overrun through an MPI buffer (which
#            -fcheck=bounds cannot see: MPI copies through C pointers) stops the run with a report

set(_dkt_release "")
set(_dkt_debug "")
if(CMAKE_Fortran_COMPILER_ID STREQUAL "GNU")
  set(_dkt_release -O3)
  if(DKTLBM_NATIVE)
    list(APPEND _dkt_release -march=native)
  endif()
  # no-array-temps: -fcheck=all would print a run-time line at every call that makes an
  # array temporary (a speed hint, not an error), burying the output of a debug run.
  # no-compare-reals: the one warning of -Wall/-Wextra left out. The code and the tests compare
  # reals exactly on purpose (a body force that is exactly zero switches forcing off; the
  # tests check bit-identical results across rank counts and exact zeros), and the warning
  # cannot tell those from accidental ones.
  set(_dkt_debug -g -O0 -Wall -Wextra -Wno-compare-reals -fcheck=all,no-array-temps
    -ffpe-trap=invalid,zero,overflow -fbacktrace)
  if(DKTLBM_WERROR)
    list(APPEND _dkt_debug -Werror)
  endif()
elseif(CMAKE_Fortran_COMPILER_ID MATCHES "^Intel")
  set(_dkt_release -O3)
  if(DKTLBM_NATIVE)
    list(APPEND _dkt_release -xHost)
  endif()
  set(_dkt_debug -g -O0 -warn all -check all -fpe0 -traceback)
  if(DKTLBM_WERROR)
    list(APPEND _dkt_debug -warn errors)
  endif()
else()
  message(WARNING "dktlbm: no tuned flags for ${CMAKE_Fortran_COMPILER_ID}; using -O3 / -g -O0")
  set(_dkt_release -O3)
  set(_dkt_debug -g -O0)
endif()

# CMake's own defaults would add a second optimisation level (-O3, -g) to dktlbm's own list;
# they are emptied while they are the defaults, and flags a user sets there are kept (and
# reported in dkt_build_flags).
foreach(_dkt_type IN ITEMS RELEASE DEBUG)
  string(STRIP "${CMAKE_Fortran_FLAGS_${_dkt_type}}" _dkt_now)
  string(STRIP "${CMAKE_Fortran_FLAGS_${_dkt_type}_INIT}" _dkt_init)
  if(_dkt_now STREQUAL _dkt_init AND NOT _dkt_now STREQUAL "")
    set(CMAKE_Fortran_FLAGS_${_dkt_type} "" CACHE STRING
      "Extra ${_dkt_type} flags (dktlbm sets its own, see cmake/DktCompilerFlags.cmake)" FORCE)
  endif()
endforeach()

string(TOUPPER "${CMAKE_BUILD_TYPE}" _dkt_config)
if(_dkt_config STREQUAL "DEBUG")
  set(_dkt_type_flags ${_dkt_debug})
elseif(_dkt_config STREQUAL "RELEASE" OR _dkt_config STREQUAL "")
  set(_dkt_type_flags ${_dkt_release})
else()
  message(FATAL_ERROR "dktlbm: CMAKE_BUILD_TYPE must be Release or Debug, not '${CMAKE_BUILD_TYPE}'")
endif()

set(DKTLBM_SANITIZE "" CACHE STRING "Sanitizer for every dktlbm target: '' (none) or 'address'")
set_property(CACHE DKTLBM_SANITIZE PROPERTY STRINGS "" address)
set(_dkt_link_flags "")
if(DKTLBM_SANITIZE STREQUAL "address")
  if(NOT CMAKE_Fortran_COMPILER_ID STREQUAL "GNU")
    message(FATAL_ERROR "dktlbm: DKTLBM_SANITIZE=address is set up for gfortran only")
  endif()
  # -O1, as AddressSanitizer recommends, and without gfortran's own run-time checks (the debug
  # build runs those): sanitized runs of the MPI and particle tests must fit in CI's time
  list(REMOVE_ITEM _dkt_type_flags -O0 -fcheck=all,no-array-temps)
  list(APPEND _dkt_type_flags -O1 -fsanitize=address -fno-omit-frame-pointer)
  set(_dkt_link_flags -fsanitize=address)
elseif(NOT DKTLBM_SANITIZE STREQUAL "")
  message(FATAL_ERROR "dktlbm: DKTLBM_SANITIZE must be '' or 'address', not '${DKTLBM_SANITIZE}'")
endif()

# Everything the compiler sees for dktlbm's sources, as one string (for dkt_build_flags).
set(DKT_FORTRAN_FLAGS "${CMAKE_Fortran_FLAGS} ${CMAKE_Fortran_FLAGS_${_dkt_config}}")
list(JOIN _dkt_type_flags " " _dkt_type_string)
string(REGEX REPLACE " +" " " DKT_FORTRAN_FLAGS "${DKT_FORTRAN_FLAGS} ${_dkt_type_string}")
string(STRIP "${DKT_FORTRAN_FLAGS}" DKT_FORTRAN_FLAGS)

#> Give a dktlbm target (library, program or test) the flags of the build type.
function(dkt_set_fortran_flags target)
  target_compile_options(${target} PRIVATE ${_dkt_type_flags})
  target_link_options(${target} PRIVATE ${_dkt_link_flags})
endfunction()
