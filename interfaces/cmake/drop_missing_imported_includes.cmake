# Passed as -DCMAKE_PROJECT_INCLUDE=... when building the interface packages inside a venv.
#
# The ROS 2 Jazzy PyPI wheels were built in a manylinux container and their exported
# *__rosidl_generator_py targets still name that container's include directories
# (/opt/python/cp311-cp311/include/python3.11, its NumPy headers). CMake refuses to
# generate when an imported target lists a directory that does not exist. At the end of
# the top-level directory's configure step, drop such entries from every imported
# target; the targets that need Python headers get the venv's through Python3::Python.

function(_evsync_drop_missing_imported_includes)
  get_property(_targets DIRECTORY "${CMAKE_SOURCE_DIR}" PROPERTY IMPORTED_TARGETS)
  foreach(_target IN LISTS _targets)
    get_target_property(_dirs ${_target} INTERFACE_INCLUDE_DIRECTORIES)
    if(NOT _dirs)
      continue()
    endif()
    set(_kept "")
    set(_dropped FALSE)
    foreach(_dir IN LISTS _dirs)
      if(_dir MATCHES "^\\$<" OR EXISTS "${_dir}")
        list(APPEND _kept "${_dir}")
      else()
        set(_dropped TRUE)
      endif()
    endforeach()
    if(_dropped)
      set_target_properties(${_target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_kept}")
    endif()
  endforeach()
endfunction()

cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL _evsync_drop_missing_imported_includes)
