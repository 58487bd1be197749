# Tree checks (label unit): the Fortran sources are formatted as fprettify with .fprettify.ini
# formats them, no Fortran line is longer than 100 characters, the Python code is ruff-clean, and
# the sources keep the structure limits (tools/check_structure.py), and docs/design.md draws
# the module graph the `use` statements give (tests/test_design_graph.py).
#
# This file has two roles. Included from tests/CMakeLists.txt it registers the tests; run as
#   cmake -DCHECK=fortran|python -DPYTHON=<python3> -DROOT=<source dir> -P tests/format.cmake
# it performs one check (files are listed when the test runs, so new files are checked too).
# To fix the Fortran format: fprettify -c .fprettify.ini src/*.f90 tests/*.f90
# To fix Python lint:        ruff check --fix postproc tests

if(NOT CMAKE_SCRIPT_MODE_FILE)
  # (tests/CMakeLists.txt stops the configure when python3 is missing)
  add_test(NAME format_fortran_fprettify
    COMMAND "${CMAKE_COMMAND}" -DCHECK=fortran "-DPYTHON=${Python3_EXECUTABLE}"
      "-DROOT=${PROJECT_SOURCE_DIR}" -P "${CMAKE_CURRENT_LIST_FILE}")
  add_test(NAME lint_python_ruff
    COMMAND "${CMAKE_COMMAND}" -DCHECK=python "-DPYTHON=${Python3_EXECUTABLE}"
      "-DROOT=${PROJECT_SOURCE_DIR}" -P "${CMAKE_CURRENT_LIST_FILE}")
  set_tests_properties(format_fortran_fprettify lint_python_ruff PROPERTIES
    LABELS unit TIMEOUT 120)
  # the structure limits of docs/design.md: files within 800 lines, procedures within 150,
  # input modules used outside the input layer only for their types (tools/check_structure.py)
  dkt_add_pytest(NAME structure_limits FILE tests/test_structure.py LABELS unit TIMEOUT 120)
  # the module graph of docs/design.md ("Modules") is that of the `use` statements in src/, and
  # its layers point one way
  dkt_add_pytest(NAME design_graph FILE tests/test_design_graph.py LABELS unit TIMEOUT 120)
  return()
endif()

# ---------------------------------------------------------------- script mode
cmake_minimum_required(VERSION 3.20)

function(_dkt_require_module module)
  execute_process(COMMAND "${PYTHON}" -c "import ${module}"
    RESULT_VARIABLE missing OUTPUT_QUIET ERROR_QUIET)
  if(missing)
    message(FATAL_ERROR "${module} is not installed for ${PYTHON}; run tools/setup.sh "
      "(or: ${PYTHON} -m pip install ${module})")
  endif()
endfunction()

if(CHECK STREQUAL "fortran")
  _dkt_require_module(fprettify)
  file(GLOB src_files RELATIVE "${ROOT}" "${ROOT}/src/*.f90")
  file(GLOB_RECURSE test_files RELATIVE "${ROOT}" "${ROOT}/tests/*.f90")
  set(files ${src_files} ${test_files})
  list(SORT files)
  if(NOT files)
    message(FATAL_ERROR "no Fortran files found under ${ROOT}/src and ${ROOT}/tests")
  endif()
  list(LENGTH files count)

  # fprettify reports a file it cannot parse on stderr and still exits 0, so both streams are
  # read: a diff on stdout or any message on stderr fails the check.
  execute_process(
    COMMAND "${PYTHON}" -c "import sys, fprettify; fprettify.run(['fprettify'] + sys.argv[1:])"
      --config-file "${ROOT}/.fprettify.ini" --diff ${files}
    WORKING_DIRECTORY "${ROOT}"
    RESULT_VARIABLE status OUTPUT_VARIABLE diff ERROR_VARIABLE messages)
  set(failed FALSE)
  if(NOT status EQUAL 0 OR NOT messages STREQUAL "")
    # fprettify repeats each warning once per pass; show each once, on one line.
    string(REGEX REPLACE "\n[ \t]+" " " messages "${messages}")
    string(REPLACE ";" "," messages "${messages}")
    string(REPLACE "\n" ";" messages "${messages}")
    list(REMOVE_DUPLICATES messages)
    list(JOIN messages "\n" messages)
    message("fprettify (exit ${status}):\n${messages}")
    set(failed TRUE)
  endif()
  if(NOT diff STREQUAL "")
    message("fprettify would change these lines (fix: fprettify -c .fprettify.ini <file>):\n"
      "${diff}")
    set(failed TRUE)
  endif()

  # Lines fprettify cannot shorten (long strings, comments) are checked here.
  set(long_lines_script [=[
import sys
bad = 0
for name in sys.argv[1:]:
    with open(name, encoding="utf-8") as f:
        for number, line in enumerate(f, 1):
            length = len(line.rstrip("\r\n"))
            if length > 100:
                print(f"{name}:{number}: {length} characters, more than 100")
                bad += 1
sys.exit(1 if bad else 0)
]=])
  execute_process(COMMAND "${PYTHON}" -c "${long_lines_script}" ${files}
    WORKING_DIRECTORY "${ROOT}" RESULT_VARIABLE status)
  if(NOT status EQUAL 0)
    set(failed TRUE)
  endif()

  if(failed)
    message(FATAL_ERROR "Fortran format check failed")
  endif()
  message("fprettify: ${count} Fortran files formatted, no line over 100 characters")

elseif(CHECK STREQUAL "python")
  _dkt_require_module(ruff)
  set(paths "")
  foreach(dir IN ITEMS postproc tests)
    file(GLOB_RECURSE py_files "${ROOT}/${dir}/*.py")
    if(py_files)
      list(APPEND paths "${dir}")
    endif()
  endforeach()
  if(NOT paths)
    message("ruff: no Python files in postproc/ or tests/ yet")
    return()
  endif()
  execute_process(
    COMMAND "${PYTHON}" -m ruff check --no-cache --config "${ROOT}/ruff.toml" ${paths}
    WORKING_DIRECTORY "${ROOT}"
    RESULT_VARIABLE status)
  if(NOT status EQUAL 0)
    message(FATAL_ERROR "ruff found problems (fix: ruff check --fix ${paths})")
  endif()

else()
  message(FATAL_ERROR "format.cmake: CHECK must be 'fortran' or 'python', not '${CHECK}'")
endif()
