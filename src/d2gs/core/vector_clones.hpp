#pragma once
// Hot loops (eval/sinkhorn, eval/imr, eval/ssim) are compiled for several x86-64 levels and picked at
// load time (GCC function multi-versioning), so a portable build still runs AVX2 / AVX-512 code where
// the CPU has it.
// Elsewhere (other compilers, other architectures, or -DD2GS_NO_TARGET_CLONES) the plain build is used.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(D2GS_NO_TARGET_CLONES)
#define D2GS_VECTOR_CLONES __attribute__((target_clones("default", "arch=x86-64-v3", "arch=x86-64-v4")))
#else
#define D2GS_VECTOR_CLONES
#endif
#define D2GS_ALWAYS_INLINE inline __attribute__((always_inline))
