#pragma once
// D2GS_HD marks the small per-Gaussian / per-pixel functions that the CPU backend and the CUDA kernels
// share unchanged: `__host__ __device__ inline` under nvcc, plain `inline` elsewhere.
#if defined(__CUDACC__)
#define D2GS_HD __host__ __device__ __forceinline__
#else
#define D2GS_HD inline
#endif
