# Finds the three OpenCV modules MGSR uses (core, imgproc, imgcodecs).
# Debian ships OpenCVConfig.cmake only in the full libopencv-dev, which pulls in ~100 packages we do not
# need; the per-module -dev packages ship headers and libraries but no config. Use the config when present,
# otherwise locate the modules directly and create the same imported targets (opencv_core, ...).
find_package(OpenCV CONFIG QUIET COMPONENTS ${OpenCV_FIND_COMPONENTS})
if(OpenCV_FOUND)
  return()
endif()

find_path(OpenCV_INCLUDE_DIR opencv2/core.hpp PATH_SUFFIXES opencv4)
set(OpenCV_LIBS)
set(_ocv_missing)
foreach(_c IN LISTS OpenCV_FIND_COMPONENTS)
  find_library(OpenCV_${_c}_LIBRARY NAMES opencv_${_c})
  if(OpenCV_${_c}_LIBRARY AND OpenCV_INCLUDE_DIR)
    if(NOT TARGET opencv_${_c})
      add_library(opencv_${_c} UNKNOWN IMPORTED)
      set_target_properties(opencv_${_c} PROPERTIES
        IMPORTED_LOCATION "${OpenCV_${_c}_LIBRARY}"
        INTERFACE_INCLUDE_DIRECTORIES "${OpenCV_INCLUDE_DIR}")
    endif()
    list(APPEND OpenCV_LIBS opencv_${_c})
  else()
    list(APPEND _ocv_missing ${_c})
  endif()
endforeach()

include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(OpenCV
  REQUIRED_VARS OpenCV_INCLUDE_DIR OpenCV_LIBS
  REASON_FAILURE_MESSAGE "missing modules: ${_ocv_missing} (run scripts/install_deps.sh)")
