#pragma once
// Per-Gaussian dropout masks, applied as the rasterizer's opacity multiplier during training only.
//
// DropGaussian (baseline, method.md §4): each Gaussian is dropped with probability r = 0.2·t/T; kept
// ones have their opacity scaled by 1/(1 − r).
//
// DD-Drop (D²GS, method.md §4): p_i = λ_layer(i) · S_i · r(t), with
//   S_i = w_d·(1 − minmax(d_i)) + w_ρ·minmax(ρ_i),  ρ_i = −mean distance to the 6 nearest Gaussians,
//   λ = 1 / 0.7 / 0.3 for the near / middle / far depth tertile, r(t) = r_min + (r_max − r_min)·min(t,T)/T;
// dropped Gaussians get multiplier 0, kept ones 1 (no rescaling; `compensate` gives kept ones 1/(1 − p_i),
// DropGaussian's rule per Gaussian, a diagnostic that neither the paper nor the release has). Depth d_i is
// the Euclidean distance to the camera centre (paper) or x_i · R_w2c[:,2] (release: no translation).
#include <cstdint>
#include <vector>

#include "d2gs/core/random.hpp"
#include "d2gs/model/gaussians.hpp"
#include "d2gs/scene/camera.hpp"
#include "d2gs/train/dd_drop_math.hpp"

namespace d2gs {

// DropGaussian's rate at iteration t of T, and its mask.
double dropgaussian_rate(int iteration, int total_iterations, double max_rate = 0.2);
void dropgaussian_mask(std::size_t n, double rate, Rng& rng, std::vector<float>& multiplier);

enum class DepthMode { Euclidean, ReleaseDot };

struct DdDropOptions {
  double weight_depth = 0.5;    // w_d
  double weight_density = 0.5;  // w_ρ
  double rate_min = 0.05;
  double rate_max = 0.3;
  int rate_iterations = 10000;  // T of the rate schedule
  bool use_depth_score = true;
  bool use_density_score = true;
  bool use_layers = true;
  double lambda_near = 1.0, lambda_middle = 0.7, lambda_far = 0.3;
  DepthMode depth_mode = DepthMode::Euclidean;
  bool compensate = false;  // kept Gaussians' opacity × 1/(1 − p_i), so that its expectation is unchanged
  // The density scores are computed at iteration 1 and every `density_refresh_every` iterations and
  // cached in between. Through densification the paper carries them along (children inherit their
  // parent's score); the release's cache (`release_density_cache`) keeps its old length instead: every
  // score 0.5 when the model grew, the first N scores when it shrank (method.md §4).
  int density_refresh_every = 500;
  bool release_density_cache = false;
};

// r(t) of DD-Drop.
double dd_drop_rate(const DdDropOptions& options, int iteration);
// The constants of p_i at an iteration (weights, λs, r(t), switches), as dd_drop_probability takes them.
DdDropTerms dd_drop_terms(const DdDropOptions& options, int iteration);
// Min-max normalisation to [0, 1]; a constant input maps to 0.
std::vector<float> minmax(const std::vector<float>& values);
// Per-Gaussian depth w.r.t. the camera, by the chosen formula.
std::vector<float> gaussian_depths(const Gaussians& model, const Camera& camera, DepthMode mode);
// Layer of each Gaussian from its depth: 0 near, 1 middle, 2 far. With s = the depths sorted ascending
// and N their count, the thresholds are t1 = s[⌊0.33·N⌋] and t2 = s[⌊0.67·N⌋]; d < t1 is near,
// t1 ≤ d < t2 middle, the rest far.
std::vector<std::uint8_t> depth_layers(const std::vector<float>& depths);
// Density scores minmax(ρ_i), ρ_i = −mean distance to the 6 nearest other Gaussians (kNN, nanoflann).
std::vector<float> density_scores(const Gaussians& model);
// Drop probabilities p_i (clamped to [0, 1]) from depths and density scores in [0, 1] (dense → 1),
// both aligned with the model.
std::vector<float> dd_drop_probabilities(const std::vector<float>& depths, const std::vector<float>& density_score,
                                         const DdDropOptions& options, int iteration);
// Bernoulli draws: multiplier 0 where dropped; elsewhere 1, or 1/(1 − p_i) with `compensate`.
void bernoulli_mask(const std::vector<float>& probabilities, Rng& rng, std::vector<float>& multiplier,
                    bool compensate = false);

}  // namespace d2gs
