# Included by .ci/build_ros_msgs.sh through CMAKE_PROJECT_INCLUDE when building interface packages
# against the ROS 2 wheels from the package index (not needed with an apt ROS install).
#
# Those wheels export imported targets (<pkg>::<pkg>__rosidl_generator_py) whose include directories
# are the wheel build machine's Python and NumPy headers (/opt/python/cp311-cp311/...). CMake refuses
# to generate with a non-existent include path, so once the project has imported every target, swap
# such paths for this interpreter's headers. Nothing in the venv is modified.

if(NOT Python3_EXECUTABLE)
  message(FATAL_ERROR "pip_wheel_fixes.cmake: pass -DPython3_EXECUTABLE=<venv python>")
endif()
execute_process(
  COMMAND "${Python3_EXECUTABLE}" -c
    "import sysconfig, numpy; print(sysconfig.get_paths()['include'] + ';' + numpy.get_include(), end='')"
  OUTPUT_VARIABLE _atsvo_py_includes
  RESULT_VARIABLE _atsvo_py_result)
if(NOT _atsvo_py_result EQUAL 0)
  message(FATAL_ERROR "pip_wheel_fixes.cmake: ${Python3_EXECUTABLE} could not report its include paths")
endif()
list(GET _atsvo_py_includes 0 ATSVO_PYTHON_INCLUDE_DIR)
list(GET _atsvo_py_includes 1 ATSVO_NUMPY_INCLUDE_DIR)

function(atsvo_fix_wheel_include_dirs)
  get_directory_property(_targets DIRECTORY "${CMAKE_SOURCE_DIR}" IMPORTED_TARGETS)
  foreach(_target IN LISTS _targets)
    get_target_property(_dirs "${_target}" INTERFACE_INCLUDE_DIRECTORIES)
    if(NOT _dirs)
      continue()
    endif()
    set(_fixed "")
    set(_changed FALSE)
    foreach(_dir IN LISTS _dirs)
      if(NOT EXISTS "${_dir}" AND _dir MATCHES "/include/python3\\.[0-9]+$")
        set(_dir "${ATSVO_PYTHON_INCLUDE_DIR}")
        set(_changed TRUE)
      elseif(NOT EXISTS "${_dir}" AND _dir MATCHES "/numpy/(_core|core)/include$")
        set(_dir "${ATSVO_NUMPY_INCLUDE_DIR}")
        set(_changed TRUE)
      endif()
      list(APPEND _fixed "${_dir}")
    endforeach()
    if(_changed)
      message(STATUS "pip_wheel_fixes: include dirs of ${_target} -> local Python/NumPy headers")
      set_target_properties("${_target}" PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_fixed}")
    endif()
  endforeach()
endfunction()

# Run after the whole CMakeLists.txt, when every dependency's targets have been imported.
cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL atsvo_fix_wheel_include_dirs)
