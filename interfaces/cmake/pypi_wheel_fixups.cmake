# Injected by interfaces/build_interfaces.py through CMAKE_PROJECT_INCLUDE; not part of the
# package itself. The ROS 2 PyPI wheels export their *__rosidl_generator_py targets with the
# wheel builder's Python and NumPy include paths (/opt/python/...), which CMake rejects at
# generate time. At the end of the top-level directory every such imported target gets this
# interpreter's include paths instead (CDW_PYTHON_INCLUDE_DIRS, set on the command line).

function(cdw_fix_python_generator_targets)
  get_property(_targets DIRECTORY "${CMAKE_SOURCE_DIR}" PROPERTY IMPORTED_TARGETS)
  foreach(_target IN LISTS _targets)
    if(_target MATCHES "__rosidl_generator_py$")
      set_target_properties("${_target}" PROPERTIES
        INTERFACE_INCLUDE_DIRECTORIES "${CDW_PYTHON_INCLUDE_DIRS}")
      message(STATUS "cdw fixup: ${_target} include dirs -> ${CDW_PYTHON_INCLUDE_DIRS}")
    endif()
  endforeach()
endfunction()

if(NOT CDW_PYTHON_INCLUDE_DIRS)
  message(FATAL_ERROR "pypi_wheel_fixups.cmake: CDW_PYTHON_INCLUDE_DIRS is not set")
endif()
cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL cdw_fix_python_generator_targets)
