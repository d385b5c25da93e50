#pragma once
// Entropic optimal transport by log-domain Sinkhorn (method.md §7 step 4).
//
// Problem: for weights a (n, Σa = 1), b (m, Σb = 1) and a cost C (n × m), find the plan
//   P = argmin_{P 1 = a, Pᵀ 1 = b} ⟨P, C⟩ − ε H(P),  H(P) = −Σ P_ij (log P_ij − 1),
// whose solution is P_ij = exp((f_i + g_j − C_ij)/ε). This is the same problem as POT's
// ot.sinkhorn(a, b, M, reg) with reg = ε. The iteration, in the dimensionless log-potentials
// φ = f/ε, ψ = g/ε (each update a log-sum-exp in double after subtracting the running maximum):
//   φ_i ← log a_i − log Σ_j exp(ψ_j − C_ij/ε)      (then)      ψ_j ← log b_j − log Σ_i exp(φ_i − C_ij/ε)
// Stopping rule: max(max_i |Δφ_i|, max_j |Δψ_j|) over one full iteration < tolerance (the change of the
// log-potentials); the final L1 marginal error Σ_i |P1 − a|_i + Σ_j |Pᵀ1 − b|_j is reported. After the last
// ψ update the column marginals are exact up to rounding, so the error is essentially the row part.
// The result is the transport cost ⟨P, C⟩ (no entropy term): what ot.sinkhorn2 returns.
//
// Parallelism: OpenMP over rows (φ update) and over columns (ψ update); every row/column is reduced by one
// thread in a fixed order, and all cross-row sums are done serially afterwards, so results are bitwise
// independent of the thread count. Exponentials use a vectorisable float exp (relative error ~1e-7) of
// arguments already reduced in double, accumulated in double.
#include <cstddef>
#include <functional>
#include <span>
#include <vector>

namespace d2gs {

// One row or column of a cost matrix: exactly one of the pointers is set.
struct CostSpan {
  const float* f32 = nullptr;
  const double* f64 = nullptr;
};

// A cost matrix as the solver reads it: a whole row or a whole column at a time, from any thread.
class CostMatrix {
public:
  virtual ~CostMatrix() = default;
  virtual std::size_t rows() const = 0;
  virtual std::size_t cols() const = 0;
  // Row i (cols() values) or column j (rows() values): a pointer into stored data, or into `scratch` (room
  // for max(rows(), cols()) doubles, owned by the calling thread) after filling it with the values.
  virtual CostSpan row(std::size_t i, double* scratch) const = 0;
  virtual CostSpan column(std::size_t j, double* scratch) const = 0;
};

// A stored cost matrix, kept in both row-major and column-major order (2 · n · m · sizeof(T) bytes) so
// both half-iterations read contiguous memory.
template <class T>
class DenseCostMatrix final : public CostMatrix {
public:
  DenseCostMatrix() = default;
  // `row_major` holds n · m values, C_ij at i · m + j. Without `with_columns` only the row-major copy is kept
  // (n · m · sizeof(T) bytes) and column() gathers a column into the scratch buffer (strided reads): enough for
  // the stabilised-kernel solver, which reads the cost by rows.
  DenseCostMatrix(std::size_t n, std::size_t m, std::vector<T> row_major, bool with_columns = true);
  std::size_t rows() const override { return n_; }
  std::size_t cols() const override { return m_; }
  CostSpan row(std::size_t i, double* scratch) const override;
  CostSpan column(std::size_t j, double* scratch) const override;
  const std::vector<T>& row_major() const { return by_row_; }

private:
  std::size_t n_ = 0, m_ = 0;
  std::vector<T> by_row_, by_col_;
};

// Evaluates every entry of `cost` once (rows in parallel) and stores it (both orientations, or rows only).
template <class T>
DenseCostMatrix<T> store_cost(const CostMatrix& cost, bool with_columns = true);

// How the iterations are evaluated (both solve the same problem with the same stopping rule):
// - LogDomain: every half-iteration a log-sum-exp over the cost (one float exp per entry), reading rows for φ and
//   columns for ψ.
// - StabilizedKernel: the scaling form (Schmitzer 2019, "Stabilized sparse scaling algorithms for entropy
//   regularized transport problems"): K_ij = exp(φ̂_i + ψ̂_j − C_ij/ε) is stored in float once per absorption
//   (n · m · 4 bytes) and an iteration is u_i = a_i / (K v)_i, v_j = b_j / (Kᵀ u)_j, both products in one pass
//   over K (no exp); φ = φ̂ + log u, ψ = ψ̂ + log v. A row whose scaling leaves [e^−τ, e^τ] (τ =
//   absorb_threshold) is updated exactly (log-sum-exp over its cost row) and its kernel row recomputed; when a
//   column scaling leaves that range, or at each ε stage, the whole kernel is recomputed (an "absorption").
//   Kernel entries below e^−87 are 0 (no subnormals): with scalings within e^±τ the omitted plan entries are
//   below e^(2τ−87). Reads the cost by rows only.
enum class SinkhornMethod { LogDomain, StabilizedKernel };

// Revision of the iterations: raised when the same options give other iterates (2: the accelerated solver's dual
// safeguard against the previous iterate; 3: against the lowest of the last `anderson_depth` iterates, and the
// residual safeguard on Σ b_j |F_j|; both 2026-12-01). Results cached under the options (the experiment runner's
// IMR) also key on it.
inline constexpr int kSinkhornRevision = 3;
const char* to_string(SinkhornMethod method);

inline constexpr int kMaxEpsilonStages = 1000;

struct SinkhornOptions {
  double epsilon = 0.1;         // ε, in the cost's units (POT's reg)
  int max_iterations = 10000;   // one iteration = one φ update + one ψ update (all ε stages together)
  double tolerance = 1e-4;      // on max |Δφ|, |Δψ| (log-potentials, dimensionless) over one iteration
  // A second way for the last ε stage to end (0: off): the L1 marginal error of the plan after an iteration's row update,
  // Σ_j b_j |1 − exp(ψ_j − ψ'_j)| (its rows are exact; ψ' is the column update), below this. The potentials of
  // components that carry almost no mass can drift for thousands of iterations while the plan, and its transport
  // cost, no longer change: max |Δφ|, |Δψ| does not weigh by mass, the marginal error does (POT stops on it).
  double marginal_tolerance = 0.0;
  // ε-scaling: solve first with ε_start, then ε_start·factor, ... down to ε, warm-starting the potentials
  // (kept in cost units f = εφ, g = εψ across stages). Intermediate stages stop at
  // max(tolerance, stage_tolerance); the last one at `tolerance`.
  // More stages than kMaxEpsilonStages (a factor next to 1) are refused.
  bool epsilon_scaling = false;
  double epsilon_start = 0.0;   // 0: max_ij C_ij (one extra pass over the cost)
  double epsilon_factor = 0.5;
  double stage_tolerance = 1e-2;
  // 0: OpenMP's default, reduced for small problems (one thread per 2^18 cost entries) because two
  // barriers per iteration cost more than they save there, above all on a busy machine. Results do not
  // depend on the thread count.
  int threads = 0;
  // Exponentials by std::exp in double instead of the vectorised float exp. The float exp makes each
  // log-sum-exp accurate to ~1e-7, so the potentials stop changing only down to ~1e-6: tolerances below
  // that need double_exp (several times slower; used for cross-checks).
  bool double_exp = false;
  // Called after every iteration with the iteration count so far (over all ε stages), that iteration's
  // change and the tolerance of the current stage: progress for long solves. Not called when empty.
  std::function<void(int iteration, double change, double tolerance)> on_iteration = nullptr;
  // Anderson acceleration (Walker & Ni 2011) of the map ψ ↦ (one plain iteration from ψ), with this many past
  // iterates (0: off, plain Sinkhorn). Same fixed point; restarted at each ε stage and by two safeguards (an
  // extrapolation that lowers the dual objective below its lowest over the last `anderson_depth` iterates is
  // replaced by the plain step; one that doubles the b-weighted residual returns to the best iterate), and plain
  // for the rest of a stage after `anderson_max_restarts` restarts in it (sinkhorn.cpp, class Anderson). In the
  // last stage, once an iteration changes the potentials by less than `tolerance`, the solve goes on with plain
  // iterations until one of them does too: the stopping rule of the plain solver.
  int anderson_depth = 0;
  // Safeguard restarts after which a stage goes on with plain iterations (< 0: no limit).
  int anderson_max_restarts = 5;
  SinkhornMethod method = SinkhornMethod::LogDomain;
  double absorb_threshold = 20.0;  // τ of the stabilised-kernel solver (log-scalings), in (0, 30]
};

// One ε stage of a solve (diagnostics).
struct SinkhornStage {
  double epsilon = 0.0;
  int iterations = 0;
  int accelerated = 0;   // of which followed by an Anderson step
  int restarts = 0;      // Anderson restarts by the safeguard
  int absorptions = 0;   // stabilised kernel: whole-kernel recomputations (one exp per entry each)
  long long row_refreshes = 0;  // stabilised kernel: rows updated exactly and recomputed
  double seconds = 0.0;
};

// The largest L1 marginal error of a plan reported converged (a solve's is below 1e-4 at the default tolerance):
// above it the stopping rule was met in rounding, not at a solution (e.g. ε 1e-300 on a cost of mean 1).
inline constexpr double kMaxConvergedMarginalError = 1e-2;

struct SinkhornResult {
  double transport_cost = 0.0;  // ⟨P, C⟩
  double marginal_error = 0.0;  // L1, rows + columns
  double last_change = 0.0;     // max |Δφ|, |Δψ| of the last iteration
  int iterations = 0;           // over all ε stages
  // The last stage reached `tolerance` (or `marginal_tolerance`) within `max_iterations`, and the final plan's
  // marginal error is at most kMaxConvergedMarginalError.
  bool converged = false;
  double epsilon = 0.0;         // the final ε
  std::vector<double> f, g;     // dual potentials in cost units (f = εφ, g = εψ)
  std::vector<SinkhornStage> stages;  // one per ε stage run
};

// Solves the problem above. a and b must be positive (zero-mass components are not supported: drop them)
// and of sizes cost.rows(), cost.cols(); their sums should agree (each is used as given).
SinkhornResult sinkhorn(std::span<const double> a, std::span<const double> b, const CostMatrix& cost,
                        const SinkhornOptions& options = {});

// The debiased divergence of three transport costs: S(A,B) − ½ S(A,A) − ½ S(B,B).
inline double debiased_divergence(double s_ab, double s_aa, double s_bb) { return s_ab - 0.5 * (s_aa + s_bb); }

// Kernels, exposed for tests and benchmarks.
namespace sinkhorn_detail {
// Vectorisable exp of a float argument; valid for any x (clamped to [-86, 88]), relative error ~2e-7.
float fast_exp(float x);
// log Σ_j exp(pot_j − c_j · inv_eps), in double with the maximum subtracted first.
double log_sum_exp(const float* c, const double* pot, double inv_eps, std::size_t count);
double log_sum_exp(const double* c, const double* pot, double inv_eps, std::size_t count);
}  // namespace sinkhorn_detail

}  // namespace d2gs
