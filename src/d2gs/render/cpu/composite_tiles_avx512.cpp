// Compositing tile loops built for x86-64-v4 (AVX-512) (composite_tiles.hpp; flags in render/CMakeLists.txt).
#define D2GS_TILE_ISA avx512
#include "d2gs/render/cpu/composite_tiles.ipp"
