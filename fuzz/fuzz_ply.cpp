// libFuzzer target: the PLY readers (Gaussian models and point clouds) on arbitrary bytes. Any input
// must either parse or throw d2gs::Error; a parsed model must be self-consistent and finite.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "d2gs/core/error.hpp"
#include "d2gs/model/ply.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  try {
    const d2gs::Gaussians g = d2gs::parse_gaussians_ply(bytes, "fuzz.ply");
    g.validate();
    for (const auto* a : {&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.sh_dc, &g.sh_rest})
      for (float v : *a)
        if (!std::isfinite(v)) std::abort();
  } catch (const d2gs::Error&) {
  }
  try {
    const d2gs::PointCloud c = d2gs::parse_point_cloud_ply(bytes, "fuzz.ply");
    if (c.colors.size() != c.positions.size()) std::abort();
    for (const auto& p : c.positions)
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) std::abort();
  } catch (const d2gs::Error&) {
  }
  return 0;
}
