#pragma once
// The Gaussian model: structure of arrays, one contiguous float array per attribute, values stored
// before activation exactly as the original 3DGS code and its PLY files (method.md §2):
//   means           N x 3   world position
//   log_scales      N x 3   scale = exp(log_scale)
//   quats           N x 4   rotation quaternion (w, x, y, z), normalised at use
//   opacity_logits  N       opacity = sigmoid(logit)
//   sh_dc           N x 3   degree-0 SH coefficient per RGB channel
//   sh_rest         N x K x 3 with K = (degree+1)^2 - 1: coefficient-major, RGB innermost
// Gradients and optimiser moments use the same type, so one function edits all of them together.
#include <cstddef>
#include <vector>

namespace d2gs {

inline constexpr int sh_coeff_count(int degree) { return (degree + 1) * (degree + 1); }
inline constexpr int kMaxShDegree = 3;
inline constexpr float kShC0 = 0.28209479177387814f;

struct Gaussians {
  int sh_degree = 0;  // degree the sh_rest arrays are sized for (0..3)
  std::vector<float> means;
  std::vector<float> log_scales;
  std::vector<float> quats;
  std::vector<float> opacity_logits;
  std::vector<float> sh_dc;
  std::vector<float> sh_rest;

  std::size_t size() const { return opacity_logits.size(); }
  bool empty() const { return opacity_logits.empty(); }
  int sh_rest_count() const { return sh_coeff_count(sh_degree) - 1; }  // K

  // Resizes every attribute for n Gaussians of the given SH degree (new entries zero, quats identity).
  void resize(std::size_t n, int degree);
  // Checks that every array has the size its shape implies; throws d2gs::Error otherwise.
  void validate() const;
};

}  // namespace d2gs
