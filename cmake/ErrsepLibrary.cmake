# errsep_library(<name> [PUBLIC_DEPS ...] [PRIVATE_DEPS ...])
# One library per layer; its sources are every .cpp under the calling directory (sub-folders group
# a concept, e.g. src/io/cnc/), its public headers
# live under include/errsep/<name>/.  New files need no CMake edit.
function(errsep_library name)
  cmake_parse_arguments(ARG "" "" "PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  file(GLOB_RECURSE _srcs CONFIGURE_DEPENDS "${CMAKE_CURRENT_SOURCE_DIR}/*.cpp")
  if(NOT _srcs)  # a layer with headers only (so far)
    add_library(errsep_${name} INTERFACE)
    target_include_directories(errsep_${name} INTERFACE
      "$<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}/include>"
      "$<BUILD_INTERFACE:${PROJECT_BINARY_DIR}/generated>")
    target_link_libraries(errsep_${name} INTERFACE ${ARG_PUBLIC_DEPS})
    add_library(errsep::${name} ALIAS errsep_${name})
    return()
  endif()
  add_library(errsep_${name} ${_srcs})  # STATIC unless BUILD_SHARED_LIBS (CMakeLists.txt)
  add_library(errsep::${name} ALIAS errsep_${name})
  target_include_directories(errsep_${name} PUBLIC
    "$<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}/include>"
    "$<BUILD_INTERFACE:${PROJECT_BINARY_DIR}/generated>")
  target_link_libraries(errsep_${name} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE ${ARG_PRIVATE_DEPS} errsep_warnings)
  # No <target>_EXPORTS define (nothing uses it): shared and static objects then compile alike.
  set_target_properties(errsep_${name} PROPERTIES POSITION_INDEPENDENT_CODE ON DEFINE_SYMBOL "")
  if(BUILD_SHARED_LIBS)  # the installed apps need them beside bin/
    install(TARGETS errsep_${name} LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR})
  endif()
endfunction()
