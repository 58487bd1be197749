# Run by `cmake --install` (install(CODE) in CMakeLists.txt) with DKT_DOC, the installed doc
# folder: the pages under it link to input/README.md and input/slurm/README.md where they are in
# the source tree, but the install puts those two READMEs in examples/ and slurm/ beside doc/.
# Point such links there, so that every relative link of the install names an installed file
# (tests/test_install.py checks it). Running it twice changes nothing more.
file(GLOB_RECURSE pages "${DKT_DOC}/*.md")
foreach(page IN LISTS pages)
  # from the page's folder back up to doc/, which stands for the source tree's root
  file(RELATIVE_PATH below "${DKT_DOC}" "${page}")
  string(REGEX MATCHALL "/" depth "${below}")
  set(up "")
  foreach(level IN LISTS depth)
    string(APPEND up "../")
  endforeach()
  file(READ "${page}" text)
  set(before "${text}")
  string(REPLACE "](${up}input/slurm/" "](${up}../slurm/" text "${text}")
  string(REPLACE "](${up}input/" "](${up}../examples/" text "${text}")
  if(NOT text STREQUAL before)
    file(WRITE "${page}" "${text}")
  endif()
endforeach()
