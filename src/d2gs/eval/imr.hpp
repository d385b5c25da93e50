#pragma once
// IMR, Inter-Model Robustness (method.md §7 steps 3-6; docs/imr.md).
//
// Cost between component i of mixture A (the source, rows) and j of mixture B (the target, columns):
//   Taylor (release):  C_ij = ‖m_i − m_j‖² + ¼ tr((Σ_i − Σ_j) Σ_j⁻¹ (Σ_i − Σ_j))   (asymmetric: B is the target)
//   exact Bures:       C_ij = ‖m_i − m_j‖² + tr(Σ_i + Σ_j − 2 (Σ_j^½ Σ_i Σ_j^½)^½)  (symmetric)
// Release choices (on by default, each switchable): the shape term is clamped to [0, max_ij ‖m_i − m_j‖²],
// then C is divided by its mean `scale` (C̃ = C / scale). With P the entropic plan for C̃ at ε:
//   S_AB = scale · ⟨P, C̃⟩ (transport cost, no entropy term),  d_AB = sqrt(S_AB),
//   IMR = ln(Σ_{A<B} d_AB² / Σ_{A<B} d_AB).
// Option: the debiased divergence D_AB = S(A,B) − ½ S(A,A) − ½ S(B,B) (each S with its own cost
// normalisation), reported beside S, with IMR_debiased = ln(Σ D / Σ sqrt(D)) (D clamped at 0).
#include <cstddef>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "d2gs/eval/gaussian_mixture.hpp"
#include "d2gs/eval/sinkhorn.hpp"

namespace d2gs {

enum class ShapeCost { TaylorBures, ExactBures };
enum class CostStorage { StoredFloat, StoredDouble, OnTheFly };
const char* to_string(ShapeCost shape);
const char* to_string(CostStorage storage);

struct CostOptions {
  ShapeCost shape = ShapeCost::TaylorBures;
  bool clamp_shape = true;  // release: shape term clamped to [0, max position term]
  bool normalize = true;    // release: C divided by its mean
};

// The IMR cost between two mixtures, computed on the fly (a row or a column at a time, in double).
// Construction makes one pass over all pairs for the clamp bound and the mean. Exact Bures costs about
// 50x more per entry than the Taylor form: store it (store_cost) rather than evaluating it every iteration.
class MixtureCost final : public CostMatrix {
public:
  MixtureCost(const GaussianMixture& source, const GaussianMixture& target, const CostOptions& options = {});
  std::size_t rows() const override { return n_; }
  std::size_t cols() const override { return m_; }
  CostSpan row(std::size_t i, double* scratch) const override;
  CostSpan column(std::size_t j, double* scratch) const override;
  // C̃_ij (normalised when options.normalize), in double.
  double entry(std::size_t i, std::size_t j) const;
  double scale() const { return scale_; }  // mean of the clamped cost (1 if not normalising, or if every cost is 0)
  double max_position_term() const { return max_position_; }     // max_ij ‖m_i − m_j‖²

private:
  double raw_entry(std::size_t i, std::size_t j) const;
  void fill_row(std::size_t i, double* out) const;
  void fill_column(std::size_t j, double* out) const;

  std::size_t n_ = 0, m_ = 0;
  CostOptions options_;
  double max_position_ = 0.0, scale_ = 1.0, inv_scale_ = 1.0, lo_ = 0.0, hi_ = 0.0;
  // Source features (structure of arrays): mean; Taylor: Σ² (xx yy zz, 2xy 2xz 2yz) and −2 tr Σ;
  // exact Bures: Σ and tr Σ.
  std::vector<double> sx_, sy_, sz_, sq_[6], st_;
  std::vector<glm::dmat3> s_cov_;
  // Target features: mean; Taylor: Σ⁻¹ (xx yy zz xy xz yz) and tr Σ; exact Bures: Σ^½ and tr Σ.
  std::vector<double> tx_, ty_, tz_, tp_[6], tt_;
  std::vector<glm::dmat3> t_sqrt_;
};

// The accelerated solver (docs/imr.md, "Solver"): ε ÷4 per stage, intermediate stages to a change of 0.1, Anderson
// acceleration of depth 10 without a cap on its safeguard restarts, ending on plain iterations with the same stopping
// rule. Same problem and value; 6× fewer iterations on a 2 000-sample fern pair, and with the stabilised-kernel
// iterations a 10 000-sample fern pair in 264 iterations, 45 CPU-s (docs/benchmarks.md). The default of d2gs imr.
inline void use_accelerated_solver(SinkhornOptions& o) {
  o.epsilon_factor = 0.25;
  o.stage_tolerance = 0.1;
  o.anderson_depth = 10;
  o.anderson_max_restarts = -1;
}

// The plain solver (d2gs imr --plain-solver; the default before the stabilised kernel): plain iterations, ε halved
// per stage, intermediate stages to 1e-2.
inline void use_plain_solver(SinkhornOptions& o) {
  o.anderson_depth = 0;
  o.epsilon_factor = 0.5;
  o.stage_tolerance = 1e-2;
  o.anderson_max_restarts = 5;
}

// The IMR default: method.md §7 (ε = 0.1, tolerance 1e-4, ≤ 10 000 iterations) with ε-scaling, stabilised-kernel
// iterations and the accelerated schedule. The same entropic plan (same ε, same stopping rule on the last stage).
inline SinkhornOptions default_imr_sinkhorn() {
  SinkhornOptions o;
  o.epsilon_scaling = true;
  o.method = SinkhornMethod::StabilizedKernel;
  use_accelerated_solver(o);
  return o;
}

struct ImrOptions {
  MixtureOptions mixture;  // samples (depth strata), sanitising
  CostOptions cost;
  // default_imr_sinkhorn(): ε-scaling, stabilised-kernel iterations, Anderson (docs/imr.md, docs/benchmarks.md);
  // use_plain_solver() and method = SinkhornMethod::LogDomain give the earlier solvers.
  SinkhornOptions sinkhorn = default_imr_sinkhorn();
  CostStorage storage = CostStorage::StoredFloat;
  bool debiased = false;   // also compute S(A,A), S(B,B) and the debiased divergence
};

// One transport problem S(A,B).
struct TransportResult {
  double transport_cost = 0.0;  // S = scale · ⟨P, C̃⟩
  double scale = 1.0;           // the cost normalisation (mean of the clamped cost)
  double max_position_term = 0.0;
  double normalized_cost = 0.0; // ⟨P, C̃⟩
  int iterations = 0;
  double marginal_error = 0.0;  // L1, of the plan for C̃
  double last_change = 0.0;
  bool converged = false;
  double seconds = 0.0;         // cost preparation + solve
  std::vector<SinkhornStage> stages;  // the solver's ε stages (iterations, time)
};

TransportResult mixture_transport(const GaussianMixture& source, const GaussianMixture& target,
                                  const ImrOptions& options);

struct ImrPair {
  std::size_t a = 0, b = 0;        // model indices, a < b; A is the source, B the target
  TransportResult transport;
  double distance = 0.0;           // d = sqrt(S)
  std::optional<double> debiased;  // D = S(A,B) − ½ S(A,A) − ½ S(B,B), when requested
};

struct ImrResult {
  std::vector<ImrPair> pairs;
  std::vector<TransportResult> self;  // S(A,A) per model, when debiased
  double imr = 0.0;                   // ln(Σ d² / Σ d) over pairs
  std::optional<double> imr_debiased; // ln(Σ D / Σ sqrt(D)), D clamped at 0
};

// One line: "ε: iterations (accelerated), seconds" per ε stage.
std::string stage_summary(const TransportResult& t);

// ln(Σ d² / Σ d); throws if there is no distance or Σ d is not positive.
double imr_from_distances(const std::vector<double>& distances);

// IMR over n ≥ 2 mixtures (already subsampled and sanitised). `progress` (optional) is called after each
// solved problem with a one-line description.
ImrResult compute_imr(const std::vector<GaussianMixture>& mixtures, const ImrOptions& options,
                      const std::function<void(const std::string&)>& progress = {});

}  // namespace d2gs
