# The include check of the room layering (cmake/Rooms.cmake): every `#include "d2gs/ROOM/..."` in a room's
# folder must name the room itself or a room it may use, and none may include the program's "cli/...".
# One line per include that climbs a layer, then a failure. Run by the build before each room's library
# (d2gs_ROOM_layering) and by ctest (room_layering):
#   cmake -DSOURCE_DIR=<repo>/src/d2gs -DRULES="core=|model=core|scene=core,model|..." [-DROOM=scene]
#         -P cmake/check_room_includes.cmake
# RULES is the table of src/d2gs/CMakeLists.txt, room=its uses; without ROOM every room is checked.
cmake_minimum_required(VERSION 3.25)

string(REPLACE "|" ";" rules "${RULES}")
set(rooms)
foreach(rule IN LISTS rules)
  string(REGEX MATCH "^([a-z0-9_]+)=(.*)$" _ "${rule}")
  set(room "${CMAKE_MATCH_1}")
  string(REPLACE "," ";" uses_${room} "${CMAKE_MATCH_2}")
  list(APPEND rooms ${room})
endforeach()
if(rooms STREQUAL "")
  message(FATAL_ERROR "check_room_includes: no rooms in RULES='${RULES}'")
endif()
set(checked ${rooms})
if(DEFINED ROOM AND NOT ROOM STREQUAL "")
  set(checked ${ROOM})
endif()

get_filename_component(repository "${SOURCE_DIR}/../.." ABSOLUTE)
set(violations 0)
foreach(room IN LISTS checked)
  if(NOT room IN_LIST rooms)
    message(FATAL_ERROR "check_room_includes: '${room}' is not a room of RULES")
  endif()
  string(REPLACE ";" ", " may_use "${uses_${room}}")
  if(may_use STREQUAL "")
    set(may_use "no other room")
  endif()
  file(GLOB_RECURSE files "${SOURCE_DIR}/${room}/*.hpp" "${SOURCE_DIR}/${room}/*.cpp" "${SOURCE_DIR}/${room}/*.ipp"
       "${SOURCE_DIR}/${room}/*.h" "${SOURCE_DIR}/${room}/*.cu" "${SOURCE_DIR}/${room}/*.cuh")
  list(SORT files)
  foreach(file IN LISTS files)
    # The library's own headers, and the program's (src/cli/), which no room may include.
    file(STRINGS "${file}" includes REGEX "^[ \t]*#[ \t]*include[ \t]*[<\"](d2gs/[^/]+|cli)/")
    foreach(include IN LISTS includes)
      string(REGEX MATCH "(d2gs/([^/]+)|cli)/[^>\"]*" target "${include}")
      set(used "${CMAKE_MATCH_2}")
      if(CMAKE_MATCH_1 STREQUAL "cli")
        set(used cli)
      endif()
      if(used STREQUAL room OR used IN_LIST uses_${room})
        continue()
      endif()
      # The line number, for editors: newlines before the include's first occurrence, plus one.
      file(READ "${file}" text)
      string(FIND "${text}" "${include}" at)
      string(SUBSTRING "${text}" 0 ${at} before)
      string(REGEX MATCHALL "\n" newlines "${before}")
      list(LENGTH newlines line)
      math(EXPR line "${line} + 1")
      file(RELATIVE_PATH shown "${repository}" "${file}")
      message(NOTICE "${shown}:${line}: error: #include \"${target}\" climbs a layer: ${room} may use only "
                     "${may_use} (the room table in src/d2gs/CMakeLists.txt)")
      math(EXPR violations "${violations} + 1")
    endforeach()
  endforeach()
endforeach()
if(violations GREATER 0)
  message(FATAL_ERROR "room layering: ${violations} include(s) outside the rooms a room may use")
endif()
