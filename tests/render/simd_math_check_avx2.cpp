// simd_math_check.ipp for x86-64-v3 (AVX2, FMA), the flags of composite_tiles_avx2.cpp (tests/render/CMakeLists.txt).
#define D2GS_TILE_ISA test_avx2
#include "simd_math_check.ipp"
