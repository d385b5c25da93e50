#include "d2gs/core/finite.hpp"

#include <omp.h>

#include <bit>
#include <cstdint>

namespace d2gs {

// A branch-free OR over the exponent bits (all ones: NaN or infinite), where a loop of std::isfinite with an
// early exit ran scalar. Each thread ORs its static share in a `simd` loop of its own: clang does not vectorise
// the reduction of a combined `parallel for simd` and (with -Werror) refuses to build it.
bool all_finite(const float* values, std::size_t count) {
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(count);
  std::uint32_t bad = 0;
#pragma omp parallel reduction(| : bad) if (n > 65536)
  {
    const std::ptrdiff_t threads = omp_get_num_threads(), t = omp_get_thread_num();
    const std::ptrdiff_t begin = n * t / threads, end = n * (t + 1) / threads;
    std::uint32_t local = 0;
#pragma omp simd reduction(| : local)
    for (std::ptrdiff_t i = begin; i < end; ++i) {
      const std::uint32_t bits = std::bit_cast<std::uint32_t>(values[i]);
      local |= static_cast<std::uint32_t>((bits & 0x7f800000u) == 0x7f800000u);
    }
    bad |= local;
  }
  return bad == 0;
}

}  // namespace d2gs
