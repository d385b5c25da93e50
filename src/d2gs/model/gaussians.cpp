#include "d2gs/model/gaussians.hpp"

#include "d2gs/core/error.hpp"

namespace d2gs {

void Gaussians::resize(std::size_t n, int degree) {
  if (degree < 0 || degree > kMaxShDegree) fail("SH degree {} is outside 0..{}", degree, kMaxShDegree);
  const std::size_t old = size();
  sh_degree = degree;
  means.resize(n * 3, 0.0f);
  log_scales.resize(n * 3, 0.0f);
  quats.resize(n * 4, 0.0f);
  for (std::size_t i = old; i < n; ++i) quats[i * 4] = 1.0f;
  opacity_logits.resize(n, 0.0f);
  sh_dc.resize(n * 3, 0.0f);
  sh_rest.resize(n * static_cast<std::size_t>(sh_rest_count()) * 3, 0.0f);
}

void Gaussians::validate() const {
  const std::size_t n = size();
  const auto check = [&](const std::vector<float>& a, std::size_t per, const char* name) {
    if (a.size() != n * per) fail("model attribute {} has {} values, expected {}", name, a.size(), n * per);
  };
  if (sh_degree < 0 || sh_degree > kMaxShDegree) fail("SH degree {} is outside 0..{}", sh_degree, kMaxShDegree);
  check(means, 3, "means");
  check(log_scales, 3, "log_scales");
  check(quats, 4, "quats");
  check(sh_dc, 3, "sh_dc");
  check(sh_rest, static_cast<std::size_t>(sh_rest_count()) * 3, "sh_rest");
}

}  // namespace d2gs
