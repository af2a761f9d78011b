# OpenCV core, imgproc and imgcodecs as imported targets. Debian ships the CMake
# package config only in the big libopencv-dev; the split -dev packages that
# hullguard needs have headers and libraries but no config, so find them here.
find_package(OpenCV QUIET COMPONENTS core imgproc imgcodecs)
if(OpenCV_FOUND)
  return()
endif()
find_path(HG_OPENCV_INCLUDE_DIR opencv2/core.hpp PATH_SUFFIXES opencv4 REQUIRED)
foreach(module core imgproc imgcodecs)
  find_library(HG_OPENCV_${module}_LIBRARY opencv_${module} REQUIRED)
  add_library(opencv_${module} UNKNOWN IMPORTED)
  set_target_properties(opencv_${module} PROPERTIES
    IMPORTED_LOCATION ${HG_OPENCV_${module}_LIBRARY}
    INTERFACE_INCLUDE_DIRECTORIES ${HG_OPENCV_INCLUDE_DIR})
endforeach()
