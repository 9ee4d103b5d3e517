# rayqConfig.cmake: find_package(rayq) for a rayq installed by `cargo cinstall` (docs/shipping.md).
#
#   find_package(rayq 0.1 REQUIRED)
#   target_link_libraries(my_renderer PRIVATE rayq::rayq)
#
# Imported targets, each with rayq.h's directory as its include directory:
#   rayq::rayq_static  the static library and the system libraries it needs
#   rayq::rayq_shared  the shared library (defined when it is installed)
#   rayq::rayq         rayq::rayq_static; rayq::rayq_shared when RAYQ_USE_SHARED is ON
#
# The system libraries are the Libs.private line of the rayq.pc installed beside the library, which
# cargo-c takes from rustc's --print native-static-libs when it builds the library: the link line for
# the platform and toolchain that built it, not a copy of one that may go stale. The OBJ helper's
# declarations stay behind RQ_WITH_OBJ, as with pkg-config: define it where you use rq_obj_*.

if(CMAKE_VERSION VERSION_LESS 3.11)
  message(FATAL_ERROR "rayq's CMake package needs CMake 3.11 or newer")
endif()
if(TARGET rayq::rayq_static)
  return()
endif()

include("${CMAKE_CURRENT_LIST_DIR}/rayqLocate.cmake")
option(RAYQ_USE_SHARED "rayq::rayq links rayq's shared library instead of its static one" OFF)

set(_rayq_include "${_rayq_prefix}/include/rayq")
if(NOT _rayq_pc OR NOT EXISTS "${_rayq_include}/rayq.h")
  set(rayq_FOUND FALSE)
  set(rayq_NOT_FOUND_MESSAGE
      "no rayq.pc under ${_rayq_prefix}/lib*/ or no ${_rayq_include}/rayq.h: is the prefix complete?")
  return()
endif()

# File names as cargo-c installs them.
if(MSVC)
  set(_rayq_static "${_rayq_libdir}/rayq.lib")
  set(_rayq_shared "${_rayq_prefix}/bin/rayq.dll")
  set(_rayq_implib "${_rayq_libdir}/rayq.dll.lib")
elseif(WIN32)
  set(_rayq_static "${_rayq_libdir}/librayq.a")
  set(_rayq_shared "${_rayq_prefix}/bin/rayq.dll")
  set(_rayq_implib "${_rayq_libdir}/librayq.dll.a")
elseif(APPLE)
  set(_rayq_static "${_rayq_libdir}/librayq.a")
  set(_rayq_shared "${_rayq_libdir}/librayq.dylib")
else()
  set(_rayq_static "${_rayq_libdir}/librayq.a")
  set(_rayq_shared "${_rayq_libdir}/librayq.so")
endif()
if(NOT EXISTS "${_rayq_static}")
  set(rayq_FOUND FALSE)
  set(rayq_NOT_FOUND_MESSAGE "rayq.pc found, but not the static library ${_rayq_static}")
  return()
endif()

# Libs.private: "-lname" becomes "name" (CMake spells it per platform: -lname, name.lib),
# "-framework X" stays one item, anything else is passed to the linker as written.
file(STRINGS "${_rayq_pc}" _rayq_private REGEX "^Libs.private:")
string(REGEX REPLACE "^Libs.private:[ \t]*" "" _rayq_private "${_rayq_private}")
separate_arguments(_rayq_tokens UNIX_COMMAND "${_rayq_private}")
set(_rayq_system_libs "")
set(_rayq_after_framework FALSE)
foreach(_rayq_token IN LISTS _rayq_tokens)
  if(_rayq_after_framework)
    list(APPEND _rayq_system_libs "-framework ${_rayq_token}")
    set(_rayq_after_framework FALSE)
  elseif(_rayq_token STREQUAL "-framework")
    set(_rayq_after_framework TRUE)
  elseif(_rayq_token MATCHES "^-l(.+)$")
    list(APPEND _rayq_system_libs "${CMAKE_MATCH_1}")
  else()
    list(APPEND _rayq_system_libs "${_rayq_token}")
  endif()
endforeach()

add_library(rayq::rayq_static STATIC IMPORTED)
set_target_properties(rayq::rayq_static PROPERTIES
  IMPORTED_LOCATION "${_rayq_static}"
  INTERFACE_INCLUDE_DIRECTORIES "${_rayq_include}"
  INTERFACE_LINK_LIBRARIES "${_rayq_system_libs}")

if(EXISTS "${_rayq_shared}")
  add_library(rayq::rayq_shared SHARED IMPORTED)
  set_target_properties(rayq::rayq_shared PROPERTIES
    IMPORTED_LOCATION "${_rayq_shared}"
    INTERFACE_INCLUDE_DIRECTORIES "${_rayq_include}")
  if(_rayq_implib)
    set_target_properties(rayq::rayq_shared PROPERTIES IMPORTED_IMPLIB "${_rayq_implib}")
  endif()
elseif(RAYQ_USE_SHARED)
  set(rayq_FOUND FALSE)
  set(rayq_NOT_FOUND_MESSAGE "RAYQ_USE_SHARED is ON but ${_rayq_shared} is not installed")
  return()
endif()

add_library(rayq::rayq INTERFACE IMPORTED)
if(RAYQ_USE_SHARED)
  set_target_properties(rayq::rayq PROPERTIES INTERFACE_LINK_LIBRARIES rayq::rayq_shared)
else()
  set_target_properties(rayq::rayq PROPERTIES INTERFACE_LINK_LIBRARIES rayq::rayq_static)
endif()

set(rayq_VERSION "${_rayq_version}")
set(rayq_FOUND TRUE)
