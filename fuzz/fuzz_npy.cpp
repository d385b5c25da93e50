// libFuzzer target: the .npy parser (and the LLFF pose validation on what it returns) on arbitrary
// bytes. Any input must either parse or throw d2gs::Error; a parsed array holds exactly
// prod(shape) values.
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "d2gs/core/error.hpp"
#include "d2gs/core/npy.hpp"
#include "d2gs/scene/llff.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  try {
    const d2gs::NpyArray a = d2gs::parse_npy(bytes, "fuzz.npy");
    std::size_t count = 1;
    for (auto d : a.shape) count *= d;
    if (count != a.values.size()) std::abort();
    try {
      const auto poses = d2gs::parse_llff_poses(a, "fuzz.npy");
      if (a.shape.size() != 2 || a.shape[1] != 17 || poses.size() != a.shape[0]) std::abort();
    } catch (const d2gs::Error&) {
    }
  } catch (const d2gs::Error&) {
  }
  return 0;
}
