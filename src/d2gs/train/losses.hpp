#pragma once
// Photometric losses with hand-written gradients (w.r.t. the rendered image), and DAFE (method.md §5).
// Images are interleaved H×W×C floats; masks are H×W bytes (1 = far region).
#include <cstdint>
#include <string>
#include <vector>

namespace d2gs {

// mean |a − b| over all C·H·W values; grad (if non-null) += scale · d/da. |x|' at 0 is 0 (as torch).
double l1_loss(const float* a, const float* b, std::size_t count, float* grad = nullptr, float scale = 1.0f);

enum class PriorKind { Depth, Disparity };  // disparity: large = near (Depth Anything V2 output)
enum class DafeMaskRule { Percentile, Threshold };
enum class DafeLossForm { Paper, Release };

// DAFE's options (method.md §5): the far-region mask comes from a prior map per training view (`prior`:
// a folder of NAME.npy maps, or "stereo": the depth maps of the training views' geometry) or, with no
// prior, from the model's own depth at iteration 1000; the loss is the L1 on that region, weighted by λ.
struct DafeOptions {
  bool enabled = true;
  std::string prior;  // folder of per-view maps, "stereo", or empty (the self-prior)
  PriorKind prior_kind = PriorKind::Disparity;
  DafeMaskRule mask_rule = DafeMaskRule::Percentile;
  double tau = 5.0;  // percent (percentile rule) or fraction (threshold rule)
  DafeLossForm loss_form = DafeLossForm::Release;
  float lambda = 1.0f;
};

// Far-region mask from a prior map. Percentile: the farthest `tau_percent` % of the valid pixels, i.e.
// depth ≥ its (100 − τ)-th percentile, or disparity ≤ its τ-th percentile (NumPy's linear
// interpolation), which is unchanged by any positive affine change of disparity. Threshold (the paper's
// equation, depth priors only): depth > τ·max depth, τ given as a fraction in [0, 1].
// `valid` (optional, same size) excludes pixels without a prior value; they are never in the mask.
std::vector<std::uint8_t> dafe_mask(const std::vector<float>& prior, PriorKind kind, DafeMaskRule rule, double tau,
                                    const std::vector<std::uint8_t>* valid = nullptr);

// DAFE loss on the masked pixels. Paper: Σ_p M_p·Σ_c |a − b| / Σ_p M_p (0 for an empty mask). Release:
// mean over all C·H·W values of |M·(a − b)|. grad (if non-null) += scale · d/da.
double dafe_loss(const float* a, const float* b, int width, int height, int channels,
                 const std::vector<std::uint8_t>& mask, DafeLossForm form, float* grad = nullptr, float scale = 1.0f);

// The stereo-depth regulariser's loss (train/methods/stereo_depth.cpp): the L1 distance between the
// render's disparity u = alpha / D (D = Σ w·z, the rasterizer's depth output, not divided by alpha) and the
// target disparity v = 1 / z, summed over the pixels that have a target (z > 0), a render depth D > 0 and
// alpha ≥ alpha_min, then divided by the number of pixels with a target and by their mean target
// disparity: a relative error, independent of the scene's scale and of how much of the view the model
// covers yet. 0 for a map without targets. grad_depth and grad_alpha (if non-null) += scale · dL/dD and
// scale · dL/dalpha (|x|' at 0 is 0); pixels below alpha_min get no gradient.
double disparity_l1_loss(const float* depth_sum, const float* alpha, const float* target_depth, std::size_t count,
                         double alpha_min, float* grad_depth = nullptr, float* grad_alpha = nullptr, float scale = 1.0f);

}  // namespace d2gs
