# rayqConfigVersion.cmake: tells find_package(rayq <version>) whether this install will do.
#
# The version is the installed rayq.pc's (rayqLocate.cmake). Compatible means the same major
# version and at least the version asked for; below 1.0, the same major and minor (0.1.x is not
# 0.2.x), as Cargo's own semver rules have it.

include("${CMAKE_CURRENT_LIST_DIR}/rayqLocate.cmake")

if(NOT _rayq_version)
  set(PACKAGE_VERSION "unknown")
  set(PACKAGE_VERSION_UNSUITABLE TRUE)
  return()
endif()

set(PACKAGE_VERSION "${_rayq_version}")
set(PACKAGE_VERSION_COMPATIBLE FALSE)
set(PACKAGE_VERSION_EXACT FALSE)
if(NOT PACKAGE_FIND_VERSION)
  set(PACKAGE_VERSION_COMPATIBLE TRUE)
elseif(NOT PACKAGE_FIND_VERSION VERSION_GREATER PACKAGE_VERSION)
  string(REGEX MATCH "^([0-9]+)\\.([0-9]+)" _rayq_have "${PACKAGE_VERSION}")
  set(_rayq_have_major "${CMAKE_MATCH_1}")
  set(_rayq_have_minor "${CMAKE_MATCH_2}")
  if(PACKAGE_FIND_VERSION_MAJOR EQUAL _rayq_have_major)
    if(NOT _rayq_have_major EQUAL 0 OR PACKAGE_FIND_VERSION_MINOR EQUAL _rayq_have_minor)
      set(PACKAGE_VERSION_COMPATIBLE TRUE)
    endif()
  endif()
  if(PACKAGE_FIND_VERSION VERSION_EQUAL PACKAGE_VERSION)
    set(PACKAGE_VERSION_EXACT TRUE)
  endif()
endif()
