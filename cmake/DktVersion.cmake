# Generates <build>/gen/dkt_version.f90 (module dkt_version) from src/dkt_version.f90.in:
# the project version, the git revision at configure time and the Fortran flags of the build.
# Sets DKT_VERSION_SOURCE (the generated file) and DKT_GIT_REVISION.

set(DKT_GIT_REVISION "unknown")
find_package(Git QUIET)
if(GIT_FOUND)
  execute_process(
    COMMAND "${GIT_EXECUTABLE}" describe --always --dirty
    WORKING_DIRECTORY "${PROJECT_SOURCE_DIR}"
    RESULT_VARIABLE _dkt_git_status
    OUTPUT_VARIABLE _dkt_git_out
    ERROR_QUIET OUTPUT_STRIP_TRAILING_WHITESPACE)
  if(_dkt_git_status EQUAL 0 AND NOT _dkt_git_out STREQUAL "")
    set(DKT_GIT_REVISION "${_dkt_git_out}")
    # A commit or checkout re-runs the configure step, so the revision a build reports is not
    # the one of an older configure.
    execute_process(
      COMMAND "${GIT_EXECUTABLE}" rev-parse --absolute-git-dir
      WORKING_DIRECTORY "${PROJECT_SOURCE_DIR}"
      OUTPUT_VARIABLE _dkt_git_dir ERROR_QUIET OUTPUT_STRIP_TRAILING_WHITESPACE)
    foreach(_dkt_git_file IN ITEMS HEAD index logs/HEAD)
      if(EXISTS "${_dkt_git_dir}/${_dkt_git_file}")
        set_property(DIRECTORY "${PROJECT_SOURCE_DIR}" APPEND PROPERTY
          CMAKE_CONFIGURE_DEPENDS "${_dkt_git_dir}/${_dkt_git_file}")
      endif()
    endforeach()
  endif()
endif()

#> A Fortran character expression for text: double-quoted pieces of at most 60 characters
#> joined by // with continuation lines, so that long flag lists stay within the line limit.
function(dkt_fortran_string_literal text out_var)
  string(REPLACE "\"" "\"\"" text "${text}")
  set(pieces "")
  string(LENGTH "${text}" remaining)
  set(start 0)
  while(remaining GREATER 60)
    string(SUBSTRING "${text}" ${start} 60 piece)
    list(APPEND pieces "\"${piece}\"")
    math(EXPR start "${start} + 60")
    math(EXPR remaining "${remaining} - 60")
  endwhile()
  string(SUBSTRING "${text}" ${start} -1 piece)
  list(APPEND pieces "\"${piece}\"")
  list(JOIN pieces " // &\n    " literal)
  set(${out_var} "${literal}" PARENT_SCOPE)
endfunction()

dkt_fortran_string_literal("${PROJECT_VERSION}" DKT_VERSION_LITERAL)
dkt_fortran_string_literal("${DKT_GIT_REVISION}" DKT_GIT_REVISION_LITERAL)
dkt_fortran_string_literal("${DKT_FORTRAN_FLAGS}" DKT_BUILD_FLAGS_LITERAL)
if(CMAKE_BUILD_TYPE)
  dkt_fortran_string_literal("${CMAKE_BUILD_TYPE}" DKT_BUILD_TYPE_LITERAL)
else()
  dkt_fortran_string_literal("Release" DKT_BUILD_TYPE_LITERAL)
endif()

set(DKT_VERSION_SOURCE "${CMAKE_BINARY_DIR}/gen/dkt_version.f90")
configure_file("${PROJECT_SOURCE_DIR}/src/dkt_version.f90.in" "${DKT_VERSION_SOURCE}" @ONLY)
