# Included with -DCMAKE_PROJECT_INCLUDE when ros/edtmap_msgs is built
# against ROS 2's PyPI wheels (test_node_rclpy.py): the wheels' CMake
# targets name Python's and NumPy's headers where the wheels were built
# (/opt/python/...); this points them at the running interpreter's.
cmake_language(DEFER CALL _edtmap_wheel_python_includes)
function(_edtmap_wheel_python_includes)
  execute_process(COMMAND "${Python3_EXECUTABLE}" -c "import sysconfig; print(sysconfig.get_paths()['include'])"
    OUTPUT_VARIABLE _python OUTPUT_STRIP_TRAILING_WHITESPACE)
  execute_process(COMMAND "${Python3_EXECUTABLE}" -c "import numpy; print(numpy.get_include())"
    OUTPUT_VARIABLE _numpy OUTPUT_STRIP_TRAILING_WHITESPACE)
  get_property(_targets DIRECTORY "${CMAKE_SOURCE_DIR}" PROPERTY IMPORTED_TARGETS)
  foreach(_target IN LISTS _targets)
    get_target_property(_dirs ${_target} INTERFACE_INCLUDE_DIRECTORIES)
    if(_dirs)
      list(TRANSFORM _dirs REPLACE "^/opt/python/[^/]+/include/python3[.0-9]*$" "${_python}")
      list(TRANSFORM _dirs REPLACE "^/opt/python/.*/numpy/_core/include$" "${_numpy}")
      set_target_properties(${_target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_dirs}")
    endif()
  endforeach()
endfunction()
