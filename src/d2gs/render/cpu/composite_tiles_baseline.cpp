// Compositing tile loops built for the x86-64 baseline (SSE2), or whatever the build's -march is; also the double kernels (composite_tiles.hpp; flags in render/CMakeLists.txt).
#define D2GS_TILE_ISA baseline
#define D2GS_TILE_WITH_DOUBLE 1
#include "d2gs/render/cpu/composite_tiles.ipp"
