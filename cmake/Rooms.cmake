# Rooms: each folder of src/d2gs is a static library d2gs_ROOM that links only the rooms it may use, and
# an include check (cmake/check_room_includes.cmake) that runs before the room compiles and fails the
# build when one of its files includes a room it may not use: all rooms share the include folder src/, so
# a link alone would not stop `#include "d2gs/train/..."` in eval/. The table of rooms and what each may
# use is src/d2gs/CMakeLists.txt, the only place that says it; the links, the check and ctest's
# room_layering all read it from there.

# What every room compiles and links with.
add_library(d2gs_room_base INTERFACE)
target_include_directories(d2gs_room_base INTERFACE ${PROJECT_SOURCE_DIR}/src)
target_link_libraries(d2gs_room_base INTERFACE glm::glm nlohmann_json::nlohmann_json fmt::fmt spdlog::spdlog
                                               OpenMP::OpenMP_CXX Threads::Threads)
target_compile_definitions(d2gs_room_base INTERFACE GLM_FORCE_XYZW_ONLY)
if(D2GS_NATIVE)
  target_compile_options(d2gs_room_base INTERFACE -march=native)
endif()

set(D2GS_ROOM_CHECK ${CMAKE_CURRENT_LIST_DIR}/check_room_includes.cmake)

# d2gs_room(NAME [USES ROOM...]): the room in folder NAME (its CMakeLists.txt adds the sources to
# d2gs_NAME). A room may use only rooms declared before it, so the table cannot hold a cycle.
function(d2gs_room room)
  cmake_parse_arguments(PARSE_ARGV 1 arg "" "" "USES")
  get_property(declared GLOBAL PROPERTY D2GS_ROOMS)
  foreach(used IN LISTS arg_USES)
    if(NOT used IN_LIST declared)
      message(FATAL_ERROR "room ${room} uses '${used}', which is not a room declared before it "
                          "(src/d2gs/CMakeLists.txt declares the rooms from the bottom layer up)")
    endif()
  endforeach()
  set_property(GLOBAL APPEND PROPERTY D2GS_ROOMS ${room})
  string(REPLACE ";" "," uses "${arg_USES}")
  set_property(GLOBAL APPEND PROPERTY D2GS_ROOM_RULES "${room}=${uses}")

  add_library(d2gs_${room} STATIC)
  set_target_properties(d2gs_${room} PROPERTIES POSITION_INDEPENDENT_CODE ON)
  list(TRANSFORM arg_USES PREPEND d2gs_ OUTPUT_VARIABLE used_targets)
  target_link_libraries(d2gs_${room} PUBLIC d2gs_room_base ${used_targets} PRIVATE d2gs_warnings)

  # The include check, again whenever a file of the room changes (a new file: at the next configure,
  # which the glob triggers).
  file(GLOB_RECURSE files CONFIGURE_DEPENDS
       ${CMAKE_CURRENT_SOURCE_DIR}/${room}/*.hpp ${CMAKE_CURRENT_SOURCE_DIR}/${room}/*.cpp
       ${CMAKE_CURRENT_SOURCE_DIR}/${room}/*.ipp ${CMAKE_CURRENT_SOURCE_DIR}/${room}/*.h
       ${CMAKE_CURRENT_SOURCE_DIR}/${room}/*.cu ${CMAKE_CURRENT_SOURCE_DIR}/${room}/*.cuh)
  set(stamp ${CMAKE_CURRENT_BINARY_DIR}/${room}/layering.stamp)
  add_custom_command(OUTPUT ${stamp}
    COMMAND ${CMAKE_COMMAND} -DSOURCE_DIR=${CMAKE_CURRENT_SOURCE_DIR} -DRULES=${room}=${uses} -DROOM=${room}
            -P ${D2GS_ROOM_CHECK}
    COMMAND ${CMAKE_COMMAND} -E touch ${stamp}
    DEPENDS ${files} ${D2GS_ROOM_CHECK}
    COMMENT "Checking that room ${room} includes only the rooms it may use"
    VERBATIM)
  add_custom_target(d2gs_${room}_layering DEPENDS ${stamp})
  add_dependencies(d2gs_${room} d2gs_${room}_layering)

  add_subdirectory(${room})
endfunction()
