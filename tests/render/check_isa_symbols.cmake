# ctest -R render_isa_symbols: the compositing tile loops are compiled once per x86-64 level
# (src/d2gs/render/cpu/composite_tiles_*.cpp). If one of those objects defined any other external
# symbol (an out-of-line inline function or template), the linker could pick the AVX-512 copy for
# code that runs on a CPU without AVX-512. Each object must export only its own kernels_*() accessors.
# Arguments: -DNM=<nm> -DOBJECTS=<list of the library's object files>
set(found 0)
foreach(obj IN LISTS OBJECTS)
  get_filename_component(name "${obj}" NAME)
  if(NOT name MATCHES "^composite_tiles_([a-z0-9]+)\\.cpp\\.o(bj)?$")
    continue()
  endif()
  set(isa "${CMAKE_MATCH_1}")
  math(EXPR found "${found} + 1")
  execute_process(COMMAND "${NM}" -C --defined-only --extern-only "${obj}"
                  OUTPUT_VARIABLE out RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "nm failed on ${obj}")
  endif()
  string(REPLACE "\n" ";" lines "${out}")
  foreach(line IN LISTS lines)
    if(line STREQUAL "")
      continue()
    endif()
    if(NOT line MATCHES " T d2gs::render::cpu::${isa}::kernels_(float|double)\\(\\)$")
      message(FATAL_ERROR "${name} exports a symbol other ISA builds may share: ${line}")
    endif()
  endforeach()
  message(STATUS "${name}: exports only d2gs::render::cpu::${isa}::kernels_*()")
endforeach()
if(found EQUAL 0)
  message(FATAL_ERROR "no composite_tiles_* objects among the library's objects")
endif()
