# Debian ships OpenCV's CMake package only with the all-modules libopencv-dev (which drags in VTK and
# friends). d2gs needs a handful of modules, installed as their own -dev packages, so this file makes
# one imported target per module from the headers and libraries those packages put in place.
find_path(D2GS_OPENCV_INCLUDE_DIR opencv2/core.hpp PATH_SUFFIXES opencv4 REQUIRED)
set(D2GS_OPENCV_TARGETS)
foreach(module IN LISTS D2GS_OPENCV_MODULES)
  find_library(D2GS_OPENCV_${module}_LIBRARY NAMES opencv_${module} REQUIRED)
  add_library(opencv::${module} UNKNOWN IMPORTED)
  set_target_properties(opencv::${module} PROPERTIES
    IMPORTED_LOCATION "${D2GS_OPENCV_${module}_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${D2GS_OPENCV_INCLUDE_DIR}")
  list(APPEND D2GS_OPENCV_TARGETS opencv::${module})
endforeach()
message(STATUS "OpenCV modules: ${D2GS_OPENCV_MODULES} (headers in ${D2GS_OPENCV_INCLUDE_DIR})")
