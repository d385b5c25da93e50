// Compositing tile loops built for x86-64-v3 (AVX2, FMA) (composite_tiles.hpp; flags in render/CMakeLists.txt).
#define D2GS_TILE_ISA avx2
#include "d2gs/render/cpu/composite_tiles.ipp"
