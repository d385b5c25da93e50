// simd_math_check.ipp for the build's own level (x86-64 baseline / SSE2 in a portable build).
#define D2GS_TILE_ISA test_baseline
#include "simd_math_check.ipp"
