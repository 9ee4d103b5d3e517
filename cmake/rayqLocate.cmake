# rayqLocate.cmake: where an installed rayq is, shared by rayqConfig.cmake and
# rayqConfigVersion.cmake (installed beside them in <prefix>/share/cmake/rayq by `cargo cinstall`,
# docs/shipping.md).
#
# Sets, without touching the cache:
#   _rayq_prefix   the install prefix, found from this file's own place (so a moved prefix works)
#   _rayq_libdir   the directory holding rayq's libraries and pkgconfig/rayq.pc ("" if none found)
#   _rayq_pc       that rayq.pc
#   _rayq_version  its Version: field, the crate's version
#
# rayq.pc is the one file cargo-c writes at install time, from the crate and from rustc, so the
# version and the system libraries are read from it rather than written down a second time here.

get_filename_component(_rayq_prefix "${CMAKE_CURRENT_LIST_DIR}/../../.." ABSOLUTE)
set(_rayq_libdir "")
set(_rayq_pc "")
set(_rayq_version "")
foreach(_rayq_dir lib lib64 "lib/${CMAKE_LIBRARY_ARCHITECTURE}")
  if(EXISTS "${_rayq_prefix}/${_rayq_dir}/pkgconfig/rayq.pc")
    set(_rayq_libdir "${_rayq_prefix}/${_rayq_dir}")
    set(_rayq_pc "${_rayq_libdir}/pkgconfig/rayq.pc")
    break()
  endif()
endforeach()
if(_rayq_pc)
  file(STRINGS "${_rayq_pc}" _rayq_version REGEX "^Version:")
  string(REGEX REPLACE "^Version:[ \t]*" "" _rayq_version "${_rayq_version}")
endif()
