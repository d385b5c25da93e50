#pragma once
// A Gaussian model seen as a Gaussian mixture, the first two steps of IMR (method.md §7):
//   1. component i: mean x_i, covariance Σ_i = R_i S_i S_iᵀ R_iᵀ (S_i = diag(exp(log_scale_i)), R_i from
//      the normalised quaternion w x y z), weight α_i / Σα with α_i = sigmoid(opacity logit);
//   2. depth-strata subsampling w.r.t. a reference camera, then covariance sanitising.
// Everything here is computed in double from the model's float attributes.
#include <array>
#include <cstddef>
#include <vector>

#include <glm/glm.hpp>

#include "d2gs/model/gaussians.hpp"
#include "d2gs/scene/camera.hpp"

namespace d2gs {

struct GaussianMixture {
  std::vector<glm::dvec3> means;
  std::vector<glm::dmat3> covariances;  // symmetric positive (semi-)definite
  std::vector<double> weights;          // sum to 1
  std::size_t size() const { return weights.size(); }
  bool empty() const { return weights.empty(); }
};

// Rotation matrix of the quaternion (w, x, y, z), normalised first; a zero quaternion gives identity.
glm::dmat3 quaternion_to_rotation(double w, double x, double y, double z);
// Σ = R S Sᵀ Rᵀ of Gaussian i of the model.
glm::dmat3 gaussian_covariance(const Gaussians& model, std::size_t i);

// The release's IMR depth of every Gaussian: |x · R_w2c[:,2]| + 1e-6 (world position dotted with the third
// column of the reference camera's world-to-camera rotation; no translation), as in its DD-Drop depth.
std::vector<double> imr_depths(const Gaussians& model, const Camera& reference);

// Depth-strata subsampling (method.md §7 step 2). Indices are sorted by depth ascending (stable: equal
// depths keep model order). With N = depths.size(), n = min(samples, N), b = N / n (integer division):
//   nearest third  = sorted ranks [0, N/3)        taken with stride b + 2,
//   middle third   = sorted ranks [N/3, 2N/3)     taken with stride b,
//   farthest third = sorted ranks [2N/3, N)       taken with stride max(1, b - 2),
// where N/3 and 2N/3 are integer divisions (N/3 = floor(N/3), 2N/3 = floor(2N/3)) and each stride starts
// at the first rank of its third. Returns the selected model indices, nearest third first, each third in
// ascending depth. The count is only approximately `samples` (e.g. N = 30 000, samples = 10 000 gives
// 2 000 + 3 334 + 10 000), as in the release. Empty input gives an empty selection.
// `phase` k ≠ 0 starts each third's stride at rank (first rank + k mod stride) instead: another subsample of
// the same rule, for measuring how much IMR depends on which components the strides happen to take (k = 0
// is the release's).
std::vector<std::size_t> depth_strata_indices(const std::vector<double>& depths, std::size_t samples,
                                              std::size_t phase = 0);

// Floor on covariance eigenvalues used by the release: (1e-3 · sqrt(max_k max_d Σ_k[d][d]))², the largest
// diagonal entry taken over all given components.
double covariance_eigenvalue_floor(const std::vector<glm::dmat3>& covariances);

// Symmetric eigen-decomposition of a 3×3 matrix by cyclic Jacobi rotations (the input is symmetrised
// first). Eigenvalues ascending; column k of `vectors` belongs to values[k]; vectors are orthonormal.
struct SymmetricEigen3 {
  glm::dvec3 values{0.0};
  glm::dmat3 vectors{1.0};
};
SymmetricEigen3 symmetric_eigen(const glm::dmat3& m);
// Eigenvalues only (ascending), closed form (trigonometric solution of the characteristic cubic): faster
// than Jacobi, absolute accuracy about 1e-15 · the largest |eigenvalue|. The input is read as symmetric.
glm::dvec3 symmetric_eigenvalues(const glm::dmat3& m);

// Sanitises in place: Σ ← (Σ + Σᵀ)/2, then eigenvalues below `floor` are raised to `floor`
// (Σ ← V diag(max(λ, floor)) Vᵀ). A matrix whose eigenvalues are all ≥ floor is only symmetrised.
// Returns the number of matrices that were clamped.
std::size_t sanitize_covariances(std::vector<glm::dmat3>& covariances, double floor);

struct MixtureOptions {
  std::size_t samples = 10000;  // n of the depth strata; 0 keeps every Gaussian (no subsampling)
  std::size_t phase = 0;        // depth_strata_indices' phase (0 = the release's subsample)
  bool sanitize = true;         // symmetrise and clamp eigenvalues (release)
};

// Model → subsampled, sanitised mixture (method.md §7 steps 1-2). The weights of the selected components
// are α_i / Σ_{k selected} α_k: renormalised over the subsample so the mixture has total mass 1 (the same
// as taking α/Σα over the whole model and renormalising the selection). The eigenvalue floor is computed
// over the selected components. Throws d2gs::Error if the model is empty or its opacities sum to 0.
GaussianMixture mixture_from_model(const Gaussians& model, const Camera& reference,
                                   const MixtureOptions& options = {});
// All Gaussians, in model order, no sanitising (the plain step 1).
GaussianMixture mixture_from_model(const Gaussians& model);
// Selected Gaussians (model indices), weights renormalised over the selection, optional sanitising.
GaussianMixture mixture_from_model(const Gaussians& model, const std::vector<std::size_t>& indices,
                                   bool sanitize);

}  // namespace d2gs
