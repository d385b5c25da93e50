#include "d2gs/geometry/patch_match.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <numeric>
#include <optional>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include "d2gs/core/error.hpp"
#include "d2gs/core/interrupt.hpp"
#include "d2gs/core/random.hpp"

namespace d2gs {

namespace {

constexpr int kMaxSources = 16;
constexpr int kMaxWindowRadius = 10;
constexpr int kMaxSamples = (2 * kMaxWindowRadius + 1) * (2 * kMaxWindowRadius + 1);
constexpr float kMaxCost = 2.0f;      // 1 − NCC at NCC = −1
constexpr float kMinVariance = 1e-5f;  // COLMAP's: below it a window has no texture

// ---- per-view data ----

struct Source {
  int view = 0;
  // Reference pixel centre (homogeneous) → source pixel: H = A + b·mᵀ with m = K_ref⁻ᵀ n / ρ.
  glm::mat3 A{1.0f};        // K_src R K_ref⁻¹
  glm::vec3 b{0.0f};        // K_src t
  glm::mat3 R{1.0f};        // reference camera frame → source camera frame
  glm::vec3 t{0.0f};
  glm::vec3 centre{0.0f};   // source camera centre in the reference frame
  float fx = 1, fy = 1, cx = 0, cy = 0;
};

struct View {
  const Camera* cam = nullptr;
  Image grey;
  int width = 0, height = 0;
  float fx = 1, fy = 1, cx = 0, cy = 0;
  float depth_min = 1, depth_max = 2;
  std::vector<Source> sources;
  glm::vec3 ray(int x, int y) const { return {(x + 0.5f - cx) / fx, (y + 0.5f - cy) / fy, 1.0f}; }
};

// The state of one reference view: a plane per pixel, its per-source photometric costs and its total cost
// (what neighbours compare when they pick a candidate).
struct State {
  std::vector<float> depth;
  std::vector<glm::vec3> normal;
  std::vector<float> total;
  std::vector<float> src_cost;  // pixel-major, sources.size() per pixel
};

// The window of sample offsets and their spatial weights (the same for every pixel).
struct Window {
  int count = 0;
  std::array<int, kMaxSamples> dx{}, dy{};
  std::array<float, kMaxSamples> spatial{};
  float inv_two_sigma_color_sq = 0;
};

Window make_window(int radius, int step, double sigma_spatial, double sigma_color) {
  Window w;
  const double ss = sigma_spatial > 0 ? sigma_spatial : static_cast<double>(radius);
  for (int dy = -radius; dy <= radius; dy += step)
    for (int dx = -radius; dx <= radius; dx += step) {
      w.dx[static_cast<std::size_t>(w.count)] = dx;
      w.dy[static_cast<std::size_t>(w.count)] = dy;
      w.spatial[static_cast<std::size_t>(w.count)] =
          static_cast<float>(std::exp(-(dx * dx + dy * dy) / (2.0 * ss * ss)));
      ++w.count;
    }
  w.inv_two_sigma_color_sq = static_cast<float>(1.0 / (2.0 * sigma_color * sigma_color));
  return w;
}

// The reference side of the NCC at one pixel: samples, bilateral weights, weighted mean and variance.
struct RefPatch {
  int count = 0;
  std::array<int, kMaxSamples> dx{}, dy{};
  std::array<float, kMaxSamples> value{}, weight{};
  float mean = 0, var = 0;
  bool textured = false;
};

void make_ref_patch(const Window& w, const Image& grey, int x, int y, RefPatch& p) {
  const float centre = grey.pixels[static_cast<std::size_t>(y) * grey.width + x];
  p.count = 0;
  float sw = 0, s = 0, ss = 0;
  for (int k = 0; k < w.count; ++k) {
    const int xx = x + w.dx[static_cast<std::size_t>(k)], yy = y + w.dy[static_cast<std::size_t>(k)];
    if (xx < 0 || yy < 0 || xx >= grey.width || yy >= grey.height) continue;
    const float v = grey.pixels[static_cast<std::size_t>(yy) * grey.width + xx];
    const float d = v - centre;
    const float wk = w.spatial[static_cast<std::size_t>(k)] * std::exp(-d * d * w.inv_two_sigma_color_sq);
    const auto i = static_cast<std::size_t>(p.count++);
    p.dx[i] = w.dx[static_cast<std::size_t>(k)];
    p.dy[i] = w.dy[static_cast<std::size_t>(k)];
    p.value[i] = v;
    p.weight[i] = wk;
    sw += wk, s += wk * v, ss += wk * v * v;
  }
  const float inv = 1.0f / sw;
  p.mean = s * inv;
  p.var = ss * inv - p.mean * p.mean;
  p.textured = p.var >= kMinVariance;
  // Normalised weights: the sums below are then weighted means directly.
  for (int i = 0; i < p.count; ++i) p.weight[static_cast<std::size_t>(i)] *= inv;
}

// 1 − NCC from the weighted sums of the source samples (s = Σwv, ss = Σwv², sr = Σwv·ref).
inline float ncc_cost(bool textured, float mean, float ref_var, float s, float ss, float sr) {
  const float var = ss - s * s;
  if (!textured || var < kMinVariance) return kMaxCost;
  const float cov = sr - s * mean;
  return std::clamp(1.0f - cov / std::sqrt(ref_var * var), 0.0f, kMaxCost);
}
inline float ncc_cost(const RefPatch& p, float s, float ss, float sr) { return ncc_cost(p.textured, p.mean, p.var, s, ss, sr); }

// 1 − NCC of the reference patch at pixel (x, y) against `src` through the homography (row-major h[9]).
float patch_cost(const RefPatch& p, const Image& src, const float* h, int x, int y) {
  float s = 0, ss = 0, sr = 0;
  const int W = src.width, Hh = src.height;
  const float* img = src.pixels.data();
  for (int i = 0; i < p.count; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const float ux = static_cast<float>(x + p.dx[k]) + 0.5f, uy = static_cast<float>(y + p.dy[k]) + 0.5f;
    const float iz = 1.0f / (h[6] * ux + h[7] * uy + h[8]);
    const float sx = (h[0] * ux + h[1] * uy + h[2]) * iz - 0.5f;
    const float sy = (h[3] * ux + h[4] * uy + h[5]) * iz - 0.5f;
    if (!(sx >= 0.0f && sy >= 0.0f && sx < static_cast<float>(W - 1) && sy < static_cast<float>(Hh - 1)))
      return kMaxCost;
    const int ix = static_cast<int>(sx), iy = static_cast<int>(sy);
    const float fx = sx - static_cast<float>(ix), fy = sy - static_cast<float>(iy);
    const float* q = img + static_cast<std::size_t>(iy) * W + ix;
    const float top = q[0] + fx * (q[1] - q[0]);
    const float bottom = q[W] + fx * (q[W + 1] - q[W]);
    const float v = top + fy * (bottom - top);
    const float wv = p.weight[k] * v;
    s += wv, ss += wv * v, sr += wv * p.value[k];
  }
  return ncc_cost(p, s, ss, sr);
}

std::vector<const Image*> greys_of(const std::vector<View>& views) {
  std::vector<const Image*> g;
  for (const View& v : views) g.push_back(&v.grey);
  return g;
}

// ---- the costs of many (plane, source) pairs of one pixel at once ----
// Every pair is one SIMD lane: lane l runs, sample by sample and in the same order, exactly the float
// operations of patch_cost (no fused multiply-add, no reassociation), so its cost is bit-identical to
// patch_cost's; only the lanes run side by side. The source images of a pyramid level lie in one buffer
// (the atlas) so that lanes of different sources gather from one base pointer.

constexpr int kLanes = 8;
constexpr int kMaxPairs = 12 * kMaxSources;  // candidates of one pixel (8 regions + 4) × sources

struct Atlas {
  std::vector<float> pixels;  // the grey images of the views, one after the other, then padding
  std::vector<int> offset;    // first pixel of each view
};

Atlas make_atlas(const std::vector<const Image*>& images) {
  Atlas a;
  std::size_t total = 0, widest = 0;
  for (const Image* im : images) total += im->pixels.size(), widest = std::max(widest, static_cast<std::size_t>(im->width));
  if (total + 2 * widest + 2 >= static_cast<std::size_t>(std::numeric_limits<int>::max()))
    fail("patch match: the images of a level are too large ({} pixels)", total);
  a.pixels.reserve(total + 2 * widest + 2);
  for (const Image* im : images) {
    a.offset.push_back(static_cast<int>(a.pixels.size()));
    a.pixels.insert(a.pixels.end(), im->pixels.begin(), im->pixels.end());
  }
  // A lane whose sample left its image reads (and discards) its image's first 2×2 pixels: padding keeps a
  // one-row last image inside the buffer.
  a.pixels.resize(total + 2 * widest + 2, 0.0f);
  return a;
}

struct CostBatch {
  int n = 0;
  alignas(32) std::array<std::array<float, kMaxPairs + kLanes>, 9> h{};  // row-major homography, per lane
  alignas(32) std::array<int, kMaxPairs + kLanes> base{}, width{}, height{}, invalid{};
  std::array<const Image*, kMaxPairs + kLanes> image{};
  std::array<float, kMaxPairs + kLanes> cost{};
};

// Lanes of several pixels of one row (batch_costs_avx2<true>).
struct PixelLanes {
  alignas(32) std::array<int, kLanes> xoff{}, pix{};
  std::array<float, kLanes> mean{}, var{};
  alignas(32) std::array<std::array<float, kLanes>, kMaxSamples> wq{}, vq{};
};

void batch_costs_scalar(const RefPatch& p, int x, int y, CostBatch& b) {
  for (int l = 0; l < b.n; ++l) {
    const auto k = static_cast<std::size_t>(l);
    if (b.invalid[k]) {
      b.cost[k] = kMaxCost;
      continue;
    }
    float h[9];
    for (std::size_t r = 0; r < 9; ++r) h[r] = b.h[r][k];
    b.cost[k] = patch_cost(p, *b.image[k], h, x, y);
  }
}

#if defined(__x86_64__) && defined(__GNUC__)
#define D2GS_PM_AVX2 1
// The horizontal neighbours (atlas[idx_l], atlas[idx_l + 1]) of 8 lanes, by 64-bit loads (cheaper than
// four gathers on the CPUs measured): lo = atlas[idx], hi = atlas[idx + 1], lane for lane.
__attribute__((target("avx2"))) inline void load_pairs(const float* atlas, __m256i idx, __m256& lo, __m256& hi) {
  alignas(32) int id[kLanes];
  _mm256_store_si256(reinterpret_cast<__m256i*>(id), idx);
  const auto pair = [&](int l) { return _mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(atlas + id[l]))); };
  const auto high = [&](__m128 a, int l) { return _mm_loadh_pi(a, reinterpret_cast<const __m64*>(atlas + id[l])); };
  const __m128 a01 = high(pair(0), 1), a23 = high(pair(2), 3), a45 = high(pair(4), 5), a67 = high(pair(6), 7);
  const __m256 A = _mm256_insertf128_ps(_mm256_castps128_ps256(a01), a45, 1);  // 0 0' 1 1' | 4 4' 5 5'
  const __m256 B = _mm256_insertf128_ps(_mm256_castps128_ps256(a23), a67, 1);  // 2 2' 3 3' | 6 6' 7 7'
  lo = _mm256_shuffle_ps(A, B, _MM_SHUFFLE(2, 0, 2, 0));
  hi = _mm256_shuffle_ps(A, B, _MM_SHUFFLE(3, 1, 3, 1));
}

// AVX2 without FMA (the target adds no "fma"): each lane's arithmetic is patch_cost's.
// With `Multi`, the lanes belong to up to kLanes pixels of one row whose windows lie inside the image (the
// same samples): lane l is pixel m->pix[l] at column x + m->xoff[l], its weights and values m->wq / m->vq
// (sample-major, one column per pixel), its mean and variance m->mean / m->var; `p` only gives the samples'
// offsets. Otherwise every lane is pixel (x, y) with reference patch p.
template <bool Multi>
__attribute__((target("avx2"))) void batch_costs_avx2(const RefPatch& p, const float* atlas, int x, int y, CostBatch& b,
                                                      const PixelLanes* m) {
  const __m256 zero = _mm256_setzero_ps(), one = _mm256_set1_ps(1.0f), half = _mm256_set1_ps(0.5f);
  const __m256 all = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
  const __m256i one_i = _mm256_set1_epi32(1);
  for (int g = 0; g < b.n; g += kLanes) {
    const auto G = static_cast<std::size_t>(g);
    const __m256 h0 = _mm256_load_ps(&b.h[0][G]), h1 = _mm256_load_ps(&b.h[1][G]), h2 = _mm256_load_ps(&b.h[2][G]);
    const __m256 h3 = _mm256_load_ps(&b.h[3][G]), h4 = _mm256_load_ps(&b.h[4][G]), h5 = _mm256_load_ps(&b.h[5][G]);
    const __m256 h6 = _mm256_load_ps(&b.h[6][G]), h7 = _mm256_load_ps(&b.h[7][G]), h8 = _mm256_load_ps(&b.h[8][G]);
    const __m256i base = _mm256_load_si256(reinterpret_cast<const __m256i*>(&b.base[G]));
    const __m256i wi = _mm256_load_si256(reinterpret_cast<const __m256i*>(&b.width[G]));
    const __m256i hi = _mm256_load_si256(reinterpret_cast<const __m256i*>(&b.height[G]));
    const __m256 wm1 = _mm256_cvtepi32_ps(_mm256_sub_epi32(wi, one_i)), hm1 = _mm256_cvtepi32_ps(_mm256_sub_epi32(hi, one_i));
    __m256 bad = _mm256_castsi256_ps(_mm256_load_si256(reinterpret_cast<const __m256i*>(&b.invalid[G])));
    __m256 s = zero, ss = zero, sr = zero;
    __m256i xoff = _mm256_setzero_si256(), pix = _mm256_setzero_si256();
    if constexpr (Multi) {
      xoff = _mm256_load_si256(reinterpret_cast<const __m256i*>(&m->xoff[G]));
      pix = _mm256_load_si256(reinterpret_cast<const __m256i*>(&m->pix[G]));
    }
    for (int i = 0; i < p.count; ++i) {
      const auto k = static_cast<std::size_t>(i);
      __m256 ux, weight, value;
      if constexpr (Multi) {
        // static_cast<float>(x_l + dx) + 0.5f of each lane: the integer sum is exact, then the same rounding.
        ux = _mm256_add_ps(_mm256_cvtepi32_ps(_mm256_add_epi32(_mm256_set1_epi32(x + p.dx[k]), xoff)), half);
        weight = _mm256_permutevar8x32_ps(_mm256_load_ps(m->wq[k].data()), pix);
        value = _mm256_permutevar8x32_ps(_mm256_load_ps(m->vq[k].data()), pix);
      } else {
        ux = _mm256_set1_ps(static_cast<float>(x + p.dx[k]) + 0.5f);
        weight = _mm256_set1_ps(p.weight[k]);
        value = _mm256_set1_ps(p.value[k]);
      }
      const __m256 uy = _mm256_set1_ps(static_cast<float>(y + p.dy[k]) + 0.5f);
      const __m256 iz =
          _mm256_div_ps(one, _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(h6, ux), _mm256_mul_ps(h7, uy)), h8));
      __m256 sx = _mm256_sub_ps(
          _mm256_mul_ps(_mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(h0, ux), _mm256_mul_ps(h1, uy)), h2), iz), half);
      __m256 sy = _mm256_sub_ps(
          _mm256_mul_ps(_mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(h3, ux), _mm256_mul_ps(h4, uy)), h5), iz), half);
      const __m256 ok = _mm256_and_ps(_mm256_and_ps(_mm256_cmp_ps(sx, zero, _CMP_GE_OQ), _mm256_cmp_ps(sy, zero, _CMP_GE_OQ)),
                                      _mm256_and_ps(_mm256_cmp_ps(sx, wm1, _CMP_LT_OQ), _mm256_cmp_ps(sy, hm1, _CMP_LT_OQ)));
      bad = _mm256_or_ps(bad, _mm256_xor_ps(ok, all));
      sx = _mm256_and_ps(sx, ok);  // a lane that left its image samples (0, 0) and is discarded
      sy = _mm256_and_ps(sy, ok);
      const __m256i ix = _mm256_cvttps_epi32(sx), iy = _mm256_cvttps_epi32(sy);
      const __m256 fx = _mm256_sub_ps(sx, _mm256_cvtepi32_ps(ix)), fy = _mm256_sub_ps(sy, _mm256_cvtepi32_ps(iy));
      const __m256i idx = _mm256_add_epi32(base, _mm256_add_epi32(_mm256_mullo_epi32(iy, wi), ix));
      const __m256i idx2 = _mm256_add_epi32(idx, wi);
#ifdef D2GS_PM_GATHER
      const __m256 q0 = _mm256_i32gather_ps(atlas, idx, 4), q1 = _mm256_i32gather_ps(atlas + 1, idx, 4);
      const __m256 q2 = _mm256_i32gather_ps(atlas, idx2, 4), q3 = _mm256_i32gather_ps(atlas + 1, idx2, 4);
#else
      __m256 q0, q1, q2, q3;
      load_pairs(atlas, idx, q0, q1);
      load_pairs(atlas, idx2, q2, q3);
#endif
      const __m256 top = _mm256_add_ps(q0, _mm256_mul_ps(fx, _mm256_sub_ps(q1, q0)));
      const __m256 bottom = _mm256_add_ps(q2, _mm256_mul_ps(fx, _mm256_sub_ps(q3, q2)));
      const __m256 v = _mm256_add_ps(top, _mm256_mul_ps(fy, _mm256_sub_ps(bottom, top)));
      const __m256 wv = _mm256_mul_ps(weight, v);
      s = _mm256_add_ps(s, wv);
      ss = _mm256_add_ps(ss, _mm256_mul_ps(wv, v));
      sr = _mm256_add_ps(sr, _mm256_mul_ps(wv, value));
    }
    alignas(32) float S[kLanes], SS[kLanes], SR[kLanes], B[kLanes];
    _mm256_store_ps(S, s);
    _mm256_store_ps(SS, ss);
    _mm256_store_ps(SR, sr);
    _mm256_store_ps(B, bad);
    for (int l = 0; l < kLanes && g + l < b.n; ++l) {
      const auto L = static_cast<std::size_t>(l);
      std::uint32_t bits;
      std::memcpy(&bits, &B[L], sizeof bits);
      if constexpr (Multi)
        b.cost[G + L] = bits ? kMaxCost : ncc_cost(true, m->mean[G + L], m->var[G + L], S[L], SS[L], SR[L]);
      else
        b.cost[G + L] = bits ? kMaxCost : ncc_cost(p, S[L], SS[L], SR[L]);
    }
  }
}
#endif

bool have_avx2() {
#ifdef D2GS_PM_AVX2
  static const bool yes = __builtin_cpu_supports("avx2") && std::getenv("D2GS_PM_SCALAR") == nullptr;
  return yes;
#else
  return false;
#endif
}

// Scores the batch's pairs against reference patch `p` at pixel (x, y): b.cost[l] = patch_cost of lane l
// (kMaxCost for an invalid lane).
void batch_costs(const RefPatch& p, const Atlas& atlas, int x, int y, CostBatch& b) {
#ifdef D2GS_PM_AVX2
  if (have_avx2()) {
    // Padding lanes up to the next multiple of kLanes: invalid, zero homography, inside the atlas.
    for (int l = b.n; l % kLanes != 0; ++l) {
      const auto k = static_cast<std::size_t>(l);
      for (std::size_t r = 0; r < 9; ++r) b.h[r][k] = 0.0f;
      b.base[k] = 0, b.width[k] = 2, b.height[k] = 2, b.invalid[k] = -1;
    }
    batch_costs_avx2<false>(p, atlas.pixels.data(), x, y, b, nullptr);
    return;
  }
#endif
  (void)atlas;
  batch_costs_scalar(p, x, y, b);
}

// H = A + b·mᵀ, m = K_ref⁻ᵀ n / ρ with ρ = n·X₀ (X₀ the point at depth z on the pixel's ray), row-major.
void homography(const View& v, const Source& s, int x, int y, float z, const glm::vec3& n, float* h) {
  const glm::vec3 X0 = z * v.ray(x, y);
  const float rho = glm::dot(n, X0);
  // K⁻¹·u = ((u − cx)/fx, (v − cy)/fy, 1): m·u = n·K⁻¹u / ρ.
  const float inv_rho = 1.0f / rho;
  const glm::vec3 m(n.x / v.fx * inv_rho, n.y / v.fy * inv_rho,
                    (n.z - n.x * v.cx / v.fx - n.y * v.cy / v.fy) * inv_rho);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) h[r * 3 + c] = s.A[c][r] + s.b[r] * m[c];
}

// Forward–backward reprojection error (px) of the point at depth z of pixel (x, y) through the source's
// depth map; `max_px` when the point leaves the source image or meets no depth there.
float geometric_error(const View& v, const Source& s, const std::vector<float>& src_depth, int src_w, int src_h,
                      int x, int y, float z, float max_px) {
  const glm::vec3 X = z * v.ray(x, y);
  const glm::vec3 Xs = s.R * X + s.t;
  if (!(Xs.z > 0.0f)) return max_px;
  const float u = s.fx * Xs.x / Xs.z + s.cx, w = s.fy * Xs.y / Xs.z + s.cy;
  if (!(u >= 0.0f && w >= 0.0f && u < static_cast<float>(src_w) && w < static_cast<float>(src_h))) return max_px;
  const float d = src_depth[static_cast<std::size_t>(static_cast<int>(w)) * src_w + static_cast<int>(u)];
  if (!(d > 0.0f)) return max_px;
  const glm::vec3 Ys((u - s.cx) / s.fx * d, (w - s.cy) / s.fy * d, d);
  const glm::vec3 Y = glm::transpose(s.R) * (Ys - s.t);
  if (!(Y.z > 0.0f)) return max_px;
  const float bu = v.fx * Y.x / Y.z + v.cx - (x + 0.5f), bv = v.fy * Y.y / Y.z + v.cy - (y + 0.5f);
  return std::min(max_px, std::sqrt(bu * bu + bv * bv));
}

// COLMAP's triangulation-angle prior: 1 above the minimum angle, falling to 0 at 0°.
float triangulation_prior(float cos_angle, float cos_min) {
  if (cos_angle <= cos_min) return 1.0f;
  const float scaled = 1.0f - (1.0f - cos_angle) / (1.0f - cos_min);
  return std::clamp(1.0f - scaled * scaled, 0.0f, 1.0f);
}

float cos_triangulation_angle(const glm::vec3& X, const glm::vec3& src_centre) {
  const glm::vec3 a = -X, b = src_centre - X;
  return glm::dot(a, b) / std::sqrt(glm::dot(a, a) * glm::dot(b, b));
}

// The pixel's own random stream: the same whatever thread draws it.
Rng pixel_rng(std::uint64_t seed, int view, std::size_t pixel, int sweep) {
  std::uint64_t h = seed ^ 0x9e3779b97f4a7c15ull;
  for (std::uint64_t v : {static_cast<std::uint64_t>(view) + 1, static_cast<std::uint64_t>(pixel) + 1,
                          static_cast<std::uint64_t>(sweep) + 1}) {
    h ^= v + 0x9e3779b97f4a7c15ull + (h << 6) + (h >> 2);
    h *= 0xbf58476d1ce4e5b9ull;
    h ^= h >> 31;
  }
  return Rng(h);
}

glm::vec3 random_normal(Rng& rng, const glm::vec3& ray) {
  // Uniform on the sphere (Marsaglia 1972), turned to face the camera.
  double a, b, s;
  do {
    a = 2.0 * rng.uniform() - 1.0;
    b = 2.0 * rng.uniform() - 1.0;
    s = a * a + b * b;
  } while (s >= 1.0);
  const double r = 2.0 * std::sqrt(1.0 - s);
  glm::vec3 n(static_cast<float>(a * r), static_cast<float>(b * r), static_cast<float>(1.0 - 2.0 * s));
  if (glm::dot(n, ray) > 0.0f) n = -n;
  return n;
}

float random_depth(Rng& rng, const View& v) {
  const double lo = 1.0 / v.depth_max, hi = 1.0 / v.depth_min;
  return static_cast<float>(1.0 / (lo + rng.uniform() * (hi - lo)));
}

glm::vec3 perturb_normal(Rng& rng, const glm::vec3& n, const glm::vec3& ray, float amount) {
  glm::vec3 r;
  do r = glm::vec3(2.0 * rng.uniform() - 1.0, 2.0 * rng.uniform() - 1.0, 2.0 * rng.uniform() - 1.0);
  while (glm::dot(r, r) > 1.0f);
  const glm::vec3 p = glm::normalize(n + amount * r);
  return glm::dot(p, ray) < 0.0f ? p : n;
}

// Checkerboard neighbours (odd Manhattan distance: the other colour) in 8 regions, after ACMH: 4 V-shaped
// regions next to the pixel and 4 long strips, one of each per direction.
struct Regions {
  static constexpr int kNear = 7, kFar = 11;
  std::array<std::array<glm::ivec2, kFar>, 8> offsets{};
  std::array<int, 8> counts{};
  Regions() {
    const std::array<glm::ivec2, kNear> near = {glm::ivec2{0, -1}, {-1, -2}, {1, -2}, {-2, -3}, {2, -3}, {-3, -4}, {3, -4}};
    for (int dir = 0; dir < 4; ++dir) {
      // rotate (x, y) → (−y, x) dir times
      const auto rot = [dir](glm::ivec2 p) {
        for (int k = 0; k < dir; ++k) p = glm::ivec2(-p.y, p.x);
        return p;
      };
      for (int i = 0; i < kNear; ++i) offsets[static_cast<std::size_t>(dir)][static_cast<std::size_t>(i)] = rot(near[static_cast<std::size_t>(i)]);
      counts[static_cast<std::size_t>(dir)] = kNear;
      for (int i = 0; i < kFar; ++i)
        offsets[static_cast<std::size_t>(4 + dir)][static_cast<std::size_t>(i)] = rot(glm::ivec2(0, -(3 + 2 * i)));
      counts[static_cast<std::size_t>(4 + dir)] = kFar;
    }
  }
};

struct Hypothesis {
  float depth;
  glm::vec3 normal;
};

class Solver {
public:
  Solver(std::vector<View>& views, const PatchMatchOptions& o)
      : views_(views), o_(o), window_(make_window(o.window_radius, o.window_step, o.sigma_spatial, o.sigma_color)),
        cos_min_angle_(static_cast<float>(std::cos(glm::radians(o.min_triangulation_angle_deg)))),
        inv_two_ncc_sigma_sq_(static_cast<float>(1.0 / (2.0 * o.ncc_sigma * o.ncc_sigma))), atlas_(make_atlas(greys_of(views))) {
    window_patch_.count = window_.count;
    window_patch_.dx = window_.dx;
    window_patch_.dy = window_.dy;
  }

  // Random planes, and their costs; returns the fraction of textured pixels.
  double initialise(int vi, State& st) {
    const View& v = views_[static_cast<std::size_t>(vi)];
    const std::size_t n = static_cast<std::size_t>(v.width) * v.height, S = v.sources.size();
    st.depth.assign(n, 0.0f);
    st.normal.assign(n, glm::vec3(0.0f));
    st.total.assign(n, kMaxCost);
    st.src_cost.assign(n * S, kMaxCost);
    prepare(vi);
    std::size_t textured = 0;
#pragma omp parallel for schedule(dynamic, 4) reduction(+ : textured)
    for (int y = 0; y < v.height; ++y) {
      RefPatch patch;
      CostBatch batch;
      for (int x = 0; x < v.width; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * v.width + x;
        Rng rng = pixel_rng(o_.seed, vi, i, 0);
        st.depth[i] = random_depth(rng, v);
        st.normal[i] = random_normal(rng, v.ray(x, y));
        if (!ref_patch(vi, v, x, y, patch)) continue;
        ++textured;
        float* c = &st.src_cost[i * S];
        batch.n = 0;
        for (std::size_t s = 0; s < S; ++s) add_pair(batch, v, v.sources[s], x, y, st.depth[i], st.normal[i]);
        batch_costs(patch, atlas_, x, y, batch);
        for (std::size_t s = 0; s < S; ++s) c[s] = batch.cost[s];
        float w[kMaxSources];
        weights(v, c, x, y, st.depth[i], w);
        st.total[i] = combine(w, c, S);
      }
    }
    return static_cast<double>(textured) / static_cast<double>(n);
  }

  // Starts from given planes (the photometric stage's), recomputing their costs; with `costs_known`, the
  // photometric costs in `st` are already those of its planes against this solver's images (the geometric
  // stage after the finest photometric one: the same planes, patches and images give the same costs, bit
  // for bit), and only the totals are recomputed.
  void initialise_from(int vi, State& st, bool costs_known = false) {
    const View& v = views_[static_cast<std::size_t>(vi)];
    const std::size_t S = v.sources.size();
    prepare(vi);
    // One plane per pixel fills only S lanes: pixels whose windows lie inside the image share the SIMD
    // lanes, kLanes / S at a time (the same costs as one by one).
    const bool shared = !costs_known && cache_.view == vi && have_avx2() && 2 * S <= static_cast<std::size_t>(kLanes);
    const int per_batch = shared ? kLanes / static_cast<int>(S) : 1;
    const int r = o_.window_radius;
#pragma omp parallel for schedule(dynamic, 4)
    for (int y = 0; y < v.height; ++y) {
      RefPatch patch;
      CostBatch batch;
      PixelLanes lanes;
      std::array<int, kLanes> pending{};
      int np = 0;
      const auto total = [&](int x) {
        const std::size_t i = static_cast<std::size_t>(y) * v.width + x;
        const float* c = &st.src_cost[i * S];
        float g[kMaxSources];
        for (std::size_t s = 0; s < S; ++s) g[s] = geo_of(v, v.sources[s], x, y, st.depth[i]);
        float w[kMaxSources];
        weights(v, c, x, y, st.depth[i], w);
        st.total[i] = combine(w, c, S, g);
      };
      const auto flush = [&] {
        score_pixels(v, st, y, pending.data(), np, batch, lanes);
        for (int q = 0; q < np; ++q) total(pending[static_cast<std::size_t>(q)]);
        np = 0;
      };
      const bool inside_rows = y >= r && y + r < v.height;
      for (int x = 0; x < v.width; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * v.width + x;
        if (shared && inside_rows && x >= r && x + r < v.width) {
          if (!cache_.textured[i]) continue;
          pending[static_cast<std::size_t>(np++)] = x;
          if (np == per_batch) flush();
          continue;
        }
        if (!ref_patch(vi, v, x, y, patch)) continue;
        if (!costs_known) {
          float* c = &st.src_cost[i * S];
          batch.n = 0;
          for (std::size_t s = 0; s < S; ++s) add_pair(batch, v, v.sources[s], x, y, st.depth[i], st.normal[i]);
          batch_costs(patch, atlas_, x, y, batch);
          for (std::size_t s = 0; s < S; ++s) c[s] = batch.cost[s];
        }
        total(x);
      }
      if (np > 0) flush();
    }
  }

  // One iteration: the red then the black half-sweep. `sweep` numbers the half-sweeps of the view (the
  // random streams); `perturbation` is the refinement's amount.
  // `wide`: candidates from all 8 regions and a random plane (exploration); otherwise only the 4 regions
  // next to the pixel and the perturbations (refinement, at the finest level).
  void iterate(int vi, State& st, int sweep, float perturbation, bool wide) {
    prepare(vi);
    for (int colour = 0; colour < 2; ++colour) half_sweep(vi, st, colour, sweep + colour, perturbation, wide);
  }

  // Source depth maps of the geometric stage (indexed by view; empty: no geometric term).
  void set_geometric(const std::vector<const std::vector<float>*>& maps) { geo_maps_ = maps; }

  // Number of sources agreeing with the pixel's plane (the filter).
  // `scratch`: the uniqueness test's cost batch (one per thread, not per pixel).
  int consistent_sources(const View& v, const State& st, int x, int y, const std::vector<const std::vector<float>*>& maps,
                         float cos_filter_angle, CostBatch& scratch) const {
    const std::size_t i = static_cast<std::size_t>(y) * v.width + x, S = v.sources.size();
    const float z = st.depth[i];
    if (!(z > 0.0f)) return 0;
    const glm::vec3 X = z * v.ray(x, y);
    std::optional<RefPatch> patch;  // the reference window of the distinctiveness test, built once per pixel
    int agree = 0;
    for (std::size_t s = 0; s < S; ++s) {
      const Source& src = v.sources[s];
      if (st.src_cost[i * S + s] > 1.0f - static_cast<float>(o_.filter_min_ncc)) continue;
      if (cos_triangulation_angle(X, src.centre) > cos_filter_angle) continue;
      const View& sv = views_[static_cast<std::size_t>(src.view)];
      if (geometric_error(v, src, *maps[static_cast<std::size_t>(src.view)], sv.width, sv.height, x, y, z,
                          static_cast<float>(o_.geom_max_px)) > static_cast<float>(o_.filter_geom_max_px))
        continue;
      if (o_.filter_min_distinctiveness > 0.0) {
        if (!patch) make_ref_patch(window_, v.grey, x, y, patch.emplace());
        if (determination(*patch, v, src, x, y, z, st.normal[i]) == Determination::Undetermined) continue;
      }
      if (o_.filter_min_uniqueness > 0.0) {
        if (!patch) make_ref_patch(window_, v.grey, x, y, patch.emplace());
        if (uniqueness(*patch, v, src, x, y, z, st.normal[i], scratch) < static_cast<float>(o_.filter_min_uniqueness))
          continue;
      }
      ++agree;
    }
    return agree;
  }

  // The projection in source s of the point at `depth` on a reference ray; false behind the source.
  static bool project_on_ray(const Source& s, const glm::vec3& ray, float depth, glm::vec2& u) {
    const glm::vec3 Xs = s.R * (depth * ray) + s.t;
    if (!(Xs.z > 0.0f)) return false;
    u = {s.fx * Xs.x / Xs.z + s.cx, s.fy * Xs.y / Xs.z + s.cy};
    return true;
  }

  // The uniqueness test: the lowest cost of the plane (z, n) of pixel (x, y) moved along the pixel's ray to
  // depths whose match in source s lies more than two window radii from the kept one, minus the kept plane's
  // cost. The depths: N + 1 uniform in inverse depth over the view's depth range, N the line's length in
  // the source over the step (filter_uniqueness_step window radii; 400 / that when an end of the range lies
  // behind the source). kMaxCost − cost when no such depth can be scored (a match that nothing else on the
  // line rivals).
  float uniqueness(const RefPatch& patch, const View& v, const Source& s, int x, int y, float z, const glm::vec3& n,
                   CostBatch& batch) const {
    if (!patch.textured) return 0.0f;
    const glm::vec3 ray = v.ray(x, y);
    const auto project = [&](float depth, glm::vec2& u) { return project_on_ray(s, ray, depth, u); };
    glm::vec2 u0, far_end, near_end;
    if (!project(z, u0)) return 0.0f;
    float h[9];
    homography(v, s, x, y, z, n, h);
    const float c0 = patch_cost(patch, views_[static_cast<std::size_t>(s.view)].grey, h, x, y);
    const float lo = 1.0f / v.depth_max, hi = 1.0f / v.depth_min;  // inverse depths
    const float r = static_cast<float>(o_.window_radius);
    const float step = r * static_cast<float>(o_.filter_uniqueness_step);
    const int max_steps = static_cast<int>(400.0 / o_.filter_uniqueness_step);
    const int N = project(1.0f / lo, far_end) && project(1.0f / hi, near_end)
                      ? std::clamp(static_cast<int>(glm::length(near_end - far_end) / step) + 1, 2, max_steps)
                      : max_steps;
    float lowest = kMaxCost;
    batch.n = 0;
    const auto flush = [&] {
      batch_costs(patch, atlas_, x, y, batch);
      for (int l = 0; l < batch.n; ++l) lowest = std::min(lowest, batch.cost[static_cast<std::size_t>(l)]);
      batch.n = 0;
    };
    for (int k = 0; k <= N; ++k) {
      const float zs = 1.0f / (lo + (hi - lo) * static_cast<float>(k) / static_cast<float>(N));
      glm::vec2 us;
      if (!project(zs, us) || glm::length(us - u0) <= 2.0f * r) continue;
      add_pair(batch, v, s, x, y, zs, n);
      if (batch.n == kMaxPairs) flush();
    }
    if (batch.n > 0) flush();
    return lowest - c0;
  }

  // What source s says of the depth of pixel (x, y) (the distinctiveness test): Determined when its cost
  // rises by at least filter_min_distinctiveness as the match moves filter_distinct_shift_px either way along
  // its epipolar line; otherwise Undetermined, except in aperture mode where a window whose cost does not
  // rise either when the match moves the same shift across the line (or that has no texture) is Flat,
  // which confirms the depth as Determined does.
  enum class Determination { Determined, Flat, Undetermined };
  Determination determination(const RefPatch& patch, const View& v, const Source& s, int x, int y, float z,
                              const glm::vec3& n) const {
    const float t = static_cast<float>(o_.filter_min_distinctiveness);
    if (o_.filter_distinct_aperture && !patch.textured) return Determination::Flat;
    Match match;
    if (distinctiveness(patch, v, s, x, y, z, n, &match) >= t) return Determination::Determined;
    if (!o_.filter_distinct_aperture || !match.valid) return Determination::Undetermined;
    return cross_rise(patch, s, match) >= t ? Determination::Undetermined : Determination::Flat;
  }

  // The smallest rise of the source's cost when the match moves filter_distinct_shift_px either way along
  // its epipolar line: the plane (z, n) of pixel (x, y) moved along the pixel's ray by the depth step that
  // shifts the point's projection in the source by that many pixels (to first order). kMaxCost − cost when
  // a moved plane leaves the source image or goes behind a camera (a match at the border is not judged
  // ambiguous by what cannot be seen). `patch` is the pixel's reference window (make_ref_patch's).
  // `match`, when given, receives the unmoved plane's homography, cost and epipolar direction (valid only
  // when the line exists).
  struct Match {
    bool valid = false;
    int x = 0, y = 0;
    float h[9]{};
    float cost = 0.0f;
    glm::vec2 along{0.0f};  // unit direction of the epipolar line in the source at the match
  };
  float distinctiveness(const RefPatch& patch, const View& v, const Source& s, int x, int y, float z,
                        const glm::vec3& n, Match* match = nullptr) const {
    if (!patch.textured) return 0.0f;
    const Image& src = views_[static_cast<std::size_t>(s.view)].grey;
    const auto project = [&](float depth, glm::vec2& u) { return project_on_ray(s, v.ray(x, y), depth, u); };
    glm::vec2 u0, u1;
    const float dz = 1e-3f * z;
    if (!project(z, u0) || !project(z + dz, u1)) return 0.0f;
    const float px_per_depth = glm::length(u1 - u0) / dz;
    if (!(px_per_depth > 0.0f)) return 0.0f;  // the ray projects to a point: no epipolar line
    const float step = static_cast<float>(o_.filter_distinct_shift_px) / px_per_depth;
    float h[9];
    homography(v, s, x, y, z, n, h);
    const float c0 = patch_cost(patch, src, h, x, y);
    if (match) {
      match->valid = true, match->x = x, match->y = y, match->cost = c0;
      std::copy(h, h + 9, match->h);
      match->along = (u1 - u0) / (px_per_depth * dz);
    }
    float rise = kMaxCost;
    for (const float zs : {z - step, z + step}) {
      if (!(zs > 0.0f) || !(std::abs(glm::dot(n, zs * v.ray(x, y))) > 0.0f)) continue;
      homography(v, s, x, y, zs, n, h);
      rise = std::min(rise, patch_cost(patch, src, h, x, y) - c0);
    }
    return rise;
  }

  // The smallest rise of the source's cost when the match moves filter_distinct_shift_px either way
  // perpendicular to the epipolar line: the unmoved plane's homography (`m`, from distinctiveness) followed by
  // that translation of the source image. kMaxCost − cost when the moved window leaves the image.
  float cross_rise(const RefPatch& patch, const Source& s, const Match& m) const {
    const Image& src = views_[static_cast<std::size_t>(s.view)].grey;
    const float shift = static_cast<float>(o_.filter_distinct_shift_px);
    float g[9], rise = kMaxCost;
    for (const float sign : {-1.0f, 1.0f}) {
      const glm::vec2 d = sign * shift * glm::vec2(-m.along.y, m.along.x);
      for (int c = 0; c < 3; ++c) {
        g[c] = m.h[c] + d.x * m.h[6 + c];
        g[3 + c] = m.h[3 + c] + d.y * m.h[6 + c];
        g[6 + c] = m.h[6 + c];
      }
      rise = std::min(rise, patch_cost(patch, src, g, m.x, m.y) - m.cost);
    }
    return rise;
  }

private:
  // The reference windows of view `vi` (bilateral weights, mean, variance: the exponentials) computed once
  // for the solver's stages on that view instead of once per half-sweep; above a memory budget they are
  // computed on the fly, as make_ref_patch does either way (the same numbers).
  void prepare(int vi) {
    if (cache_.view == vi) return;
    const View& v = views_[static_cast<std::size_t>(vi)];
    const std::size_t n = static_cast<std::size_t>(v.width) * v.height, K = static_cast<std::size_t>(window_.count);
    constexpr std::size_t kBudgetBytes = std::size_t{768} << 20;
    cache_.view = -1;
    if (n * K * sizeof(float) > kBudgetBytes) return;
    cache_.weight.resize(n * K);
    cache_.mean.resize(n);
    cache_.var.resize(n);
    cache_.textured.resize(n);
#pragma omp parallel for schedule(dynamic, 4)
    for (int y = 0; y < v.height; ++y) {
      RefPatch p;
      for (int x = 0; x < v.width; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * v.width + x;
        make_ref_patch(window_, v.grey, x, y, p);
        cache_.textured[i] = p.textured ? 1 : 0;
        cache_.mean[i] = p.mean;
        cache_.var[i] = p.var;
        std::copy(p.weight.begin(), p.weight.begin() + p.count, cache_.weight.begin() + static_cast<std::ptrdiff_t>(i * K));
      }
    }
    cache_.view = vi;
  }

  // The reference patch of pixel (x, y) of view vi (make_ref_patch's, from the cache when it holds the
  // view); false, with `p` unspecified, when the window has no texture.
  bool ref_patch(int vi, const View& v, int x, int y, RefPatch& p) const {
    if (cache_.view != vi) {
      make_ref_patch(window_, v.grey, x, y, p);
      return p.textured;
    }
    const std::size_t i = static_cast<std::size_t>(y) * v.width + x;
    if (!cache_.textured[i]) return false;
    const float* weight = &cache_.weight[i * static_cast<std::size_t>(window_.count)];
    const Image& grey = v.grey;
    p.count = 0;
    for (int k = 0; k < window_.count; ++k) {
      const int xx = x + window_.dx[static_cast<std::size_t>(k)], yy = y + window_.dy[static_cast<std::size_t>(k)];
      if (xx < 0 || yy < 0 || xx >= grey.width || yy >= grey.height) continue;
      const auto j = static_cast<std::size_t>(p.count++);
      p.dx[j] = window_.dx[static_cast<std::size_t>(k)];
      p.dy[j] = window_.dy[static_cast<std::size_t>(k)];
      p.value[j] = grey.pixels[static_cast<std::size_t>(yy) * grey.width + xx];
      p.weight[j] = weight[j];
    }
    p.mean = cache_.mean[i];
    p.var = cache_.var[i];
    p.textured = true;
    return true;
  }

  // The photometric costs (st.src_cost) of the current planes of pixels xs[0..np) of row y, side by side:
  // their windows lie inside the image and the view is in the cache (AVX2 only).
  void score_pixels(const View& v, State& st, int y, const int* xs, int np, CostBatch& b, PixelLanes& m) const {
#ifdef D2GS_PM_AVX2
    const std::size_t S = v.sources.size(), K = static_cast<std::size_t>(window_.count);
    const float* grey = v.grey.pixels.data();
    b.n = 0;
    for (int q = 0; q < np; ++q) {
      const int x = xs[q];
      const std::size_t i = static_cast<std::size_t>(y) * v.width + x;
      const float* w = &cache_.weight[i * K];
      for (std::size_t k = 0; k < K; ++k) {
        m.wq[k][static_cast<std::size_t>(q)] = w[k];
        m.vq[k][static_cast<std::size_t>(q)] =
            grey[static_cast<std::size_t>(y + window_.dy[k]) * v.width + static_cast<std::size_t>(x + window_.dx[k])];
      }
      for (std::size_t s = 0; s < S; ++s) {
        const auto l = static_cast<std::size_t>(b.n);
        add_pair(b, v, v.sources[s], x, y, st.depth[i], st.normal[i]);
        m.xoff[l] = x - xs[0];
        m.pix[l] = q;
        m.mean[l] = cache_.mean[i];
        m.var[l] = cache_.var[i];
      }
    }
    for (int l = b.n; l % kLanes != 0; ++l) {
      const auto k = static_cast<std::size_t>(l);
      for (std::size_t row = 0; row < 9; ++row) b.h[row][k] = 0.0f;
      b.base[k] = 0, b.width[k] = 2, b.height[k] = 2, b.invalid[k] = -1;
      m.xoff[k] = 0, m.pix[k] = 0;
    }
    batch_costs_avx2<true>(window_patch_, atlas_.pixels.data(), xs[0], y, b, &m);
    for (int q = 0; q < np; ++q) {
      const std::size_t i = static_cast<std::size_t>(y) * v.width + xs[q];
      for (std::size_t s = 0; s < S; ++s) st.src_cost[i * S + s] = b.cost[static_cast<std::size_t>(q) * S + s];
    }
#else
    (void)v, (void)st, (void)y, (void)xs, (void)np, (void)b, (void)m;
    fail("patch match: shared lanes need AVX2");
#endif
  }

  // Appends the pair (the plane at depth z with normal n at pixel (x, y), source s) to the batch; a plane
  // behind the camera or seen edge-on is an invalid lane (cost kMaxCost).
  void add_pair(CostBatch& b, const View& v, const Source& s, int x, int y, float z, const glm::vec3& n) const {
    const auto l = static_cast<std::size_t>(b.n++);
    const View& sv = views_[static_cast<std::size_t>(s.view)];
    b.image[l] = &sv.grey;
    b.base[l] = atlas_.offset[static_cast<std::size_t>(s.view)];
    b.width[l] = sv.grey.width;
    b.height[l] = sv.grey.height;
    if (!(z > 0.0f) || !(glm::dot(n, v.ray(x, y)) < 0.0f)) {
      b.invalid[l] = -1;
      for (std::size_t r = 0; r < 9; ++r) b.h[r][l] = 0.0f;
      return;
    }
    b.invalid[l] = 0;
    float h[9];
    homography(v, s, x, y, z, n, h);
    for (std::size_t r = 0; r < 9; ++r) b.h[r][l] = h[static_cast<std::size_t>(r)];
  }

  float geo_of(const View& v, const Source& s, int x, int y, float z) const {
    if (geo_maps_.empty()) return 0.0f;
    const View& sv = views_[static_cast<std::size_t>(s.view)];
    return geometric_error(v, s, *geo_maps_[static_cast<std::size_t>(s.view)], sv.width, sv.height, x, y, z,
                           static_cast<float>(o_.geom_max_px));
  }

  void weights(const View& v, const float* c, int x, int y, float z, float* w) const {
    const glm::vec3 X = z * v.ray(x, y);
    float sum = 0;
    for (std::size_t s = 0; s < v.sources.size(); ++s) {
      w[s] = std::exp(-c[s] * c[s] * inv_two_ncc_sigma_sq_) *
             triangulation_prior(cos_triangulation_angle(X, v.sources[s].centre), cos_min_angle_);
      sum += w[s];
    }
    if (!(sum > 1e-12f)) {
      for (std::size_t s = 0; s < v.sources.size(); ++s) w[s] = 1.0f / static_cast<float>(v.sources.size());
      return;
    }
    for (std::size_t s = 0; s < v.sources.size(); ++s) w[s] /= sum;
  }

  float combine(const float* w, const float* c, std::size_t S, const float* g = nullptr) const {
    float t = 0;
    for (std::size_t s = 0; s < S; ++s) t += w[s] * (c[s] + (g ? static_cast<float>(o_.geom_weight) * g[s] : 0.0f));
    return t;
  }

  void half_sweep(int vi, State& st, int colour, int sweep, float perturbation, bool wide) {
    const View& v = views_[static_cast<std::size_t>(vi)];
    const std::size_t S = v.sources.size();
    const bool geo = !geo_maps_.empty();
#pragma omp parallel for schedule(dynamic, 4)
    for (int y = 0; y < v.height; ++y) {
      RefPatch patch;
      CostBatch batch;
      for (int x = (y + colour) & 1; x < v.width; x += 2) {
        const std::size_t i = static_cast<std::size_t>(y) * v.width + x;
        if (!ref_patch(vi, v, x, y, patch)) continue;
        Rng rng = pixel_rng(o_.seed, vi, i, sweep);
        const glm::vec3 ray = v.ray(x, y);
        float* cur_cost = &st.src_cost[i * S];
        float w[kMaxSources], g[kMaxSources];
        weights(v, cur_cost, x, y, st.depth[i], w);
        for (std::size_t s = 0; s < S; ++s) g[s] = geo ? geo_of(v, v.sources[s], x, y, st.depth[i]) : 0.0f;
        float best_total = combine(w, cur_cost, S, geo ? g : nullptr);
        Hypothesis best{st.depth[i], st.normal[i]};
        float best_cost[kMaxSources];
        std::copy(cur_cost, cur_cost + S, best_cost);

        // Candidates: the cheapest neighbour of each region (its plane carried to this pixel's ray), then
        // refinements of the current plane and a random plane.
        constexpr int kRefine = 4;
        std::array<Hypothesis, 8 + kRefine> cand{};
        int nc = 0;
        for (std::size_t r = 0; r < (wide ? 8u : 4u); ++r) {
          float lowest = std::numeric_limits<float>::max();
          int bx = -1, by = -1;
          for (int k = 0; k < regions_.counts[r]; ++k) {
            const int xx = x + regions_.offsets[r][static_cast<std::size_t>(k)].x;
            const int yy = y + regions_.offsets[r][static_cast<std::size_t>(k)].y;
            if (xx < 0 || yy < 0 || xx >= v.width || yy >= v.height) continue;
            const float t = st.total[static_cast<std::size_t>(yy) * v.width + xx];
            if (t < lowest) lowest = t, bx = xx, by = yy;
          }
          if (bx < 0) continue;
          const std::size_t j = static_cast<std::size_t>(by) * v.width + bx;
          const glm::vec3 nn = st.normal[j];
          const glm::vec3 Xn = st.depth[j] * v.ray(bx, by);
          const float denom = glm::dot(nn, ray);
          float z = st.depth[j];
          if (denom < -1e-3f) {
            const float zt = glm::dot(nn, Xn) / denom;
            if (zt > 0.5f * v.depth_min && zt < 2.0f * v.depth_max) z = zt;
          }
          cand[static_cast<std::size_t>(nc++)] = {z, nn};
        }
        // Depth and normal perturbed apart at the iteration's amount (COLMAP's: depth ×(1 ± p), normal
        // rotated by up to about p), both together at an eighth of it (the fine step that makes the
        // last digits), and a random plane while exploring.
        const float zc = st.depth[i];
        const auto perturb_depth = [&](float amount) {
          return std::clamp(zc * (1.0f + amount * static_cast<float>(2.0 * rng.uniform() - 1.0)), v.depth_min,
                            v.depth_max);
        };
        const float fine = 0.125f * perturbation;
        cand[static_cast<std::size_t>(nc++)] = {perturb_depth(perturbation), st.normal[i]};
        cand[static_cast<std::size_t>(nc++)] = {zc, perturb_normal(rng, st.normal[i], ray, perturbation)};
        const float zf = perturb_depth(fine);
        cand[static_cast<std::size_t>(nc++)] = {zf, perturb_normal(rng, st.normal[i], ray, fine)};
        if (wide) {
          const float zr = random_depth(rng, v);
          cand[static_cast<std::size_t>(nc++)] = {zr, random_normal(rng, ray)};
        }

        batch.n = 0;
        for (int k = 0; k < nc; ++k)
          for (std::size_t s = 0; s < S; ++s)
            add_pair(batch, v, v.sources[s], x, y, cand[static_cast<std::size_t>(k)].depth,
                     cand[static_cast<std::size_t>(k)].normal);
        batch_costs(patch, atlas_, x, y, batch);
        float gc[kMaxSources];
        for (int k = 0; k < nc; ++k) {
          const Hypothesis& hyp = cand[static_cast<std::size_t>(k)];
          const float* c = &batch.cost[static_cast<std::size_t>(k) * S];
          for (std::size_t s = 0; s < S; ++s) gc[s] = geo ? geo_of(v, v.sources[s], x, y, hyp.depth) : 0.0f;
          const float t = combine(w, c, S, geo ? gc : nullptr);
          if (t < best_total) {
            best_total = t;
            best = hyp;
            std::copy(c, c + S, best_cost);
          }
        }
        st.depth[i] = best.depth;
        st.normal[i] = best.normal;
        std::copy(best_cost, best_cost + S, cur_cost);
        st.total[i] = best_total;
      }
    }
  }

  std::vector<View>& views_;
  const PatchMatchOptions& o_;
  Window window_;
  Regions regions_;
  float cos_min_angle_, inv_two_ncc_sigma_sq_;
  std::vector<const std::vector<float>*> geo_maps_;
  Atlas atlas_;
  RefPatch window_patch_;  // the window's sample offsets (of a pixel whose window lies inside the image)
  struct RefCache {
    int view = -1;
    std::vector<float> weight;  // window_.count per pixel: make_ref_patch's normalised weights
    std::vector<float> mean, var;
    std::vector<std::uint8_t> textured;
  } cache_;
};

}  // namespace

void validate(const PatchMatchOptions& o) {
  if (o.window_radius < 1 || o.window_radius > kMaxWindowRadius)
    fail("patch match: window radius must be in 1..{}, got {}", kMaxWindowRadius, o.window_radius);
  if (o.window_step < 1 || o.window_step > o.window_radius)
    fail("patch match: window step must be in 1..{} (the radius), got {}", o.window_radius, o.window_step);
  if (!(o.sigma_color > 0)) fail("patch match: sigma_color must be positive, got {}", o.sigma_color);
  if (!(o.ncc_sigma > 0)) fail("patch match: ncc_sigma must be positive, got {}", o.ncc_sigma);
  if (o.levels < 1 || o.levels > 4) fail("patch match: pyramid levels must be in 1..4, got {}", o.levels);
  if (o.iterations < 1) fail("patch match: iterations must be at least 1, got {}", o.iterations);
  if (o.fine_iterations < 0) fail("patch match: fine iterations must be ≥ 0, got {}", o.fine_iterations);
  if (o.geometric_iterations < 0) fail("patch match: geometric iterations must be ≥ 0, got {}", o.geometric_iterations);
  if (o.max_source_views < 1 || o.max_source_views > kMaxSources)
    fail("patch match: max source views must be in 1..{}, got {}", kMaxSources, o.max_source_views);
  if (!(o.geom_weight >= 0) || !(o.geom_max_px > 0))
    fail("patch match: geometric weight must be ≥ 0 and its maximum positive");
  if (o.filter_min_consistent < 0) fail("patch match: filter_min_consistent must be ≥ 0");
  if (!(o.filter_geom_max_px > 0))
    fail("patch match: the filter's largest forward-backward error must be positive, got {} px", o.filter_geom_max_px);
  if (!(o.filter_min_distinctiveness >= 0 && o.filter_min_distinctiveness <= kMaxCost))
    fail("patch match: the filter's smallest distinctiveness must be in [0, 2], got {}", o.filter_min_distinctiveness);
  if (!(o.filter_distinct_shift_px > 0 && o.filter_distinct_shift_px <= 100))
    fail("patch match: the distinctiveness shift must be in (0, 100] px, got {}", o.filter_distinct_shift_px);
  if (!(o.filter_min_uniqueness >= 0 && o.filter_min_uniqueness <= kMaxCost))
    fail("patch match: the filter's smallest uniqueness must be in [0, 2], got {}", o.filter_min_uniqueness);
  if (!(o.filter_uniqueness_step >= 0.05 && o.filter_uniqueness_step <= 4.0))
    fail("patch match: the uniqueness test's step must be in [0.05, 4] window radii, got {}", o.filter_uniqueness_step);
  if (o.filter_distinct_aperture && !(o.filter_min_distinctiveness > 0.0))
    fail("patch match: the aperture mode of the distinctiveness test needs its threshold "
         "(--pm-filter-min-distinctiveness > 0)");
  if (!(o.filter_min_ncc >= -1 && o.filter_min_ncc <= 1))
    fail("patch match: the filter's smallest NCC must be in [-1, 1], got {}", o.filter_min_ncc);
  if (!(o.filter_min_triangulation_angle_deg >= 0 && o.filter_min_triangulation_angle_deg < 90))
    fail("patch match: the filter's smallest triangulation angle must be in [0, 90) degrees, got {}",
         o.filter_min_triangulation_angle_deg);
}

Image to_grey(const Image& image) {
  Image g(image.width, image.height, 1);
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x)
      g.at(x, y, 0) = image.channels >= 3 ? 0.299f * image.at(x, y, 0) + 0.587f * image.at(x, y, 1) +
                                                0.114f * image.at(x, y, 2)
                                          : image.at(x, y, 0);
  return g;
}

glm::dmat3 plane_homography(const Camera& ref, const Camera& src, int x, int y, double z, const glm::dvec3& n) {
  const glm::dmat3 R = src.R_world_to_cam * glm::transpose(ref.R_world_to_cam);
  const glm::dvec3 t = src.t_world_to_cam - R * ref.t_world_to_cam;
  const glm::dvec3 X0 = z * glm::dvec3((x + 0.5 - ref.cx) / ref.fx, (y + 0.5 - ref.cy) / ref.fy, 1.0);
  const double rho = glm::dot(n, X0);
  glm::dmat3 Kr(1.0), Ks(1.0);  // column-major: K[col][row]
  Kr[0][0] = ref.fx, Kr[1][1] = ref.fy, Kr[2][0] = ref.cx, Kr[2][1] = ref.cy;
  Ks[0][0] = src.fx, Ks[1][1] = src.fy, Ks[2][0] = src.cx, Ks[2][1] = src.cy;
  return Ks * (R + glm::outerProduct(t, n) / rho) * glm::inverse(Kr);
}

double plane_depth_at(const Camera& c, int x1, int y1, double z1, const glm::dvec3& n, int x2, int y2) {
  const glm::dvec3 r1((x1 + 0.5 - c.cx) / c.fx, (y1 + 0.5 - c.cy) / c.fy, 1.0);
  const glm::dvec3 r2((x2 + 0.5 - c.cx) / c.fx, (y2 + 0.5 - c.cy) / c.fy, 1.0);
  const double denom = glm::dot(n, r2);
  if (std::abs(denom) < 1e-6) return z1;
  return glm::dot(n, z1 * r1) / denom;
}

double bilateral_ncc_cost(const Image& ref, const Image& src, const glm::dmat3& H, int x, int y, int radius, int step,
                          double sigma_spatial, double sigma_color) {
  if (ref.channels != 1 || src.channels != 1) fail("patch match: NCC takes grey images");
  if (radius > kMaxWindowRadius) fail("patch match: window radius must be at most {}", kMaxWindowRadius);
  const Window w = make_window(radius, step, sigma_spatial, sigma_color);
  RefPatch p;
  make_ref_patch(w, ref, x, y, p);
  float h[9];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) h[r * 3 + c] = static_cast<float>(H[c][r]);
  return patch_cost(p, src, h, x, y);
}

std::vector<double> bilateral_ncc_costs(const Image& ref, const std::vector<const Image*>& sources,
                                        const std::vector<glm::dmat3>& homographies, int x, int y, int radius, int step,
                                        double sigma_spatial, double sigma_color) {
  if (sources.size() != homographies.size()) fail("patch match: {} sources and {} homographies", sources.size(), homographies.size());
  if (sources.size() > static_cast<std::size_t>(kMaxPairs)) fail("patch match: at most {} pairs at once", kMaxPairs);
  if (radius > kMaxWindowRadius) fail("patch match: window radius must be at most {}", kMaxWindowRadius);
  for (const Image* s : sources)
    if (ref.channels != 1 || s->channels != 1) fail("patch match: NCC takes grey images");
  const Window w = make_window(radius, step, sigma_spatial, sigma_color);
  RefPatch p;
  make_ref_patch(w, ref, x, y, p);
  const Atlas atlas = make_atlas(sources);
  CostBatch b;
  for (std::size_t l = 0; l < sources.size(); ++l) {
    b.image[l] = sources[l];
    b.base[l] = atlas.offset[l];
    b.width[l] = sources[l]->width;
    b.height[l] = sources[l]->height;
    b.invalid[l] = 0;
    for (std::size_t r = 0; r < 3; ++r)
      for (std::size_t c = 0; c < 3; ++c) b.h[r * 3 + c][l] = static_cast<float>(homographies[l][static_cast<glm::length_t>(c)][static_cast<glm::length_t>(r)]);
  }
  b.n = static_cast<int>(sources.size());
  batch_costs(p, atlas, x, y, b);
  return std::vector<double>(b.cost.begin(), b.cost.begin() + b.n);
}

namespace {

// The views at one level of the pyramid: grey images area-resampled by `scale` (1 = as given), intrinsics
// scaled with them (pixel centres at +0.5 keep u' = u·s exact), sources with their transforms.
std::vector<View> make_views(const std::vector<const Camera*>& cameras, const std::vector<Image>& greys,
                             const std::vector<std::pair<double, double>>& ranges, const PatchMatchOptions& o,
                             double scale) {
  const std::size_t n = cameras.size();
  std::vector<View> views(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Camera& c = *cameras[i];
    View& v = views[i];
    v.cam = &c;
    v.width = std::max(1, static_cast<int>(std::lround(c.width * scale)));
    v.height = std::max(1, static_cast<int>(std::lround(c.height * scale)));
    v.grey = scale == 1.0 ? greys[i] : resize_area(greys[i], v.width, v.height);
    const double sx = static_cast<double>(v.width) / c.width, sy = static_cast<double>(v.height) / c.height;
    v.fx = static_cast<float>(c.fx * sx), v.fy = static_cast<float>(c.fy * sy);
    v.cx = static_cast<float>(c.cx * sx), v.cy = static_cast<float>(c.cy * sy);
    v.depth_min = static_cast<float>(ranges[i].first), v.depth_max = static_cast<float>(ranges[i].second);
  }
  for (std::size_t i = 0; i < n; ++i) {
    const Camera& c = *cameras[i];
    View& v = views[i];
    // Sources: the other views by distance of their centres, coincident centres excluded.
    std::vector<std::size_t> order;
    for (std::size_t j = 0; j < n; ++j)
      if (j != i && glm::length(cameras[j]->center_world() - c.center_world()) > 1e-9) order.push_back(j);
    if (order.empty()) fail("patch match: {}: every other view shares its camera centre", c.image_name);
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      return glm::length(cameras[a]->center_world() - c.center_world()) <
             glm::length(cameras[b]->center_world() - c.center_world());
    });
    order.resize(std::min(order.size(), static_cast<std::size_t>(o.max_source_views)));
    for (std::size_t j : order) {
      const Camera& s = *cameras[j];
      const View& sv = views[j];
      Source src;
      src.view = static_cast<int>(j);
      const glm::dmat3 R = s.R_world_to_cam * glm::transpose(c.R_world_to_cam);
      const glm::dvec3 t = s.t_world_to_cam - R * c.t_world_to_cam;
      glm::dmat3 Kr(1.0), Ks(1.0);  // column-major: K[col][row]
      Kr[0][0] = v.fx, Kr[1][1] = v.fy, Kr[2][0] = v.cx, Kr[2][1] = v.cy;
      Ks[0][0] = sv.fx, Ks[1][1] = sv.fy, Ks[2][0] = sv.cx, Ks[2][1] = sv.cy;
      src.A = glm::mat3(Ks * R * glm::inverse(Kr));
      src.b = glm::vec3(Ks * t);
      src.R = glm::mat3(R);
      src.t = glm::vec3(t);
      src.centre = glm::vec3(-glm::transpose(R) * t);
      src.fx = sv.fx, src.fy = sv.fy, src.cx = sv.cx, src.cy = sv.cy;
      v.sources.push_back(src);
    }
  }
  return views;
}

// Each pixel of the finer level takes the plane of the coarser pixel it lies in, carried to its own ray.
void upsample(const View& coarse, const State& cs, const View& fine, State& fs) {
  const std::size_t n = static_cast<std::size_t>(fine.width) * fine.height, S = fine.sources.size();
  fs.depth.assign(n, 0.0f);
  fs.normal.assign(n, glm::vec3(0.0f));
  fs.total.assign(n, kMaxCost);
  fs.src_cost.assign(n * S, kMaxCost);
  const float sx = static_cast<float>(coarse.width) / fine.width, sy = static_cast<float>(coarse.height) / fine.height;
  for (int y = 0; y < fine.height; ++y)
    for (int x = 0; x < fine.width; ++x) {
      const int xc = std::min(coarse.width - 1, static_cast<int>((x + 0.5f) * sx));
      const int yc = std::min(coarse.height - 1, static_cast<int>((y + 0.5f) * sy));
      const std::size_t j = static_cast<std::size_t>(yc) * coarse.width + xc, i = static_cast<std::size_t>(y) * fine.width + x;
      const glm::vec3 nrm = cs.normal[j];
      const glm::vec3 X = cs.depth[j] * coarse.ray(xc, yc);
      const float denom = glm::dot(nrm, fine.ray(x, y));
      float z = cs.depth[j];
      if (denom < -1e-3f) {
        const float zt = glm::dot(nrm, X) / denom;
        if (zt >= fine.depth_min && zt <= fine.depth_max) z = zt;
      }
      fs.depth[i] = z;
      fs.normal[i] = nrm;
    }
}

}  // namespace

std::vector<PatchMatchMap> patch_match_stereo(const std::vector<const Camera*>& cameras,
                                              const std::vector<const Image*>& images,
                                              const std::vector<std::pair<double, double>>& depth_ranges,
                                              const PatchMatchOptions& o) {
  validate(o);
  const std::size_t n = cameras.size();
  if (n < 2) fail("patch match: needs at least 2 views, got {}", n);
  if (images.size() != n || depth_ranges.size() != n)
    fail("patch match: {} cameras, {} images and {} depth ranges", n, images.size(), depth_ranges.size());
  std::vector<Image> greys(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Camera& c = *cameras[i];
    if (images[i]->width != c.width || images[i]->height != c.height)
      fail("patch match: {}: image is {}x{}, camera {}x{}", c.image_name, images[i]->width, images[i]->height, c.width,
           c.height);
    const auto [near, far] = depth_ranges[i];
    if (!(near > 0) || !(far > near) || !std::isfinite(far))
      fail("patch match: {}: invalid depth range {}..{}", c.image_name, near, far);
    greys[i] = to_grey(*images[i]);
  }

  // Coarse to fine: the exploring iterations at the coarsest level, refinement at each finer one.
  std::vector<State> states(n);
  std::vector<View> views;
  int sweep = 1, step = 0;  // half-sweeps done (random streams), perturbation halvings done
  for (int level = o.levels - 1; level >= 0; --level) {
    std::vector<View> level_views = make_views(cameras, greys, depth_ranges, o, std::ldexp(1.0, -level));
    Solver solver(level_views, o);
    const bool coarsest = level == o.levels - 1;
    const int iterations = coarsest ? o.iterations : o.fine_iterations;
    for (std::size_t i = 0; i < n; ++i) {
      if (coarsest) {
        const double textured = solver.initialise(static_cast<int>(i), states[i]);
        if (textured < 0.01)
          fail("patch match: {}: the image has no texture ({:.2f} % of the pixels have any contrast in their window)",
               cameras[i]->image_name, 100.0 * textured);
      } else {
        State coarse = std::move(states[i]);
        upsample(views[i], coarse, level_views[i], states[i]);
        solver.initialise_from(static_cast<int>(i), states[i]);
      }
      for (int it = 0; it < iterations; ++it) {
        check_interrupted("during the stereo");
        solver.iterate(static_cast<int>(i), states[i], sweep + 2 * it, std::pow(0.5f, static_cast<float>(step + it)),
                       coarsest);
      }
    }
    sweep += 2 * iterations;
    step += iterations;
    views = std::move(level_views);
  }
  Solver solver(views, o);
  // Geometric stage: each view against the photometric depth maps of the others.
  if (o.geometric_iterations > 0) {
    std::vector<std::vector<float>> photometric(n);
    for (std::size_t i = 0; i < n; ++i) photometric[i] = states[i].depth;
    std::vector<const std::vector<float>*> maps(n);
    for (std::size_t i = 0; i < n; ++i) maps[i] = &photometric[i];
    solver.set_geometric(maps);
    for (std::size_t i = 0; i < n; ++i) {
      solver.initialise_from(static_cast<int>(i), states[i], /*costs_known=*/true);
      for (int it = 0; it < o.geometric_iterations; ++it) {
        check_interrupted("during the stereo");
        solver.iterate(static_cast<int>(i), states[i], sweep + 2 * it, std::pow(0.5f, static_cast<float>(step + it)),
                       false);
      }
    }
  }
  // Filter against the final maps of the other views.
  std::vector<std::vector<float>> final_depth(n);
  for (std::size_t i = 0; i < n; ++i) final_depth[i] = states[i].depth;
  std::vector<const std::vector<float>*> maps(n);
  for (std::size_t i = 0; i < n; ++i) maps[i] = &final_depth[i];
  const float cos_filter = static_cast<float>(std::cos(glm::radians(o.filter_min_triangulation_angle_deg)));
  std::vector<PatchMatchMap> out(n);
  for (std::size_t i = 0; i < n; ++i) {
    const View& v = views[i];
    const State& st = states[i];
    PatchMatchMap& m = out[i];
    const std::size_t np = static_cast<std::size_t>(v.width) * v.height;
    m.depth.width = v.width, m.depth.height = v.height;
    m.depth.depth.assign(np, 0.0f);
    m.normals.assign(np, glm::vec3(0.0f));
    m.cost.assign(np, kMaxCost);
#pragma omp parallel for schedule(dynamic, 4)
    for (int y = 0; y < v.height; ++y) {
      CostBatch scratch;
      for (int x = 0; x < v.width; ++x) {
        const std::size_t p = static_cast<std::size_t>(y) * v.width + x;
        if (st.total[p] >= kMaxCost) continue;  // untextured: never scored
        if (o.filter_min_consistent > 0 &&
            solver.consistent_sources(v, st, x, y, maps, cos_filter, scratch) < o.filter_min_consistent)
          continue;
        m.depth.depth[p] = st.depth[p];
        m.normals[p] = st.normal[p];
        float c = 0;
        for (std::size_t s = 0; s < v.sources.size(); ++s) c += st.src_cost[p * v.sources.size() + s];
        m.cost[p] = c / static_cast<float>(v.sources.size());
      }
    }
  }
  return out;
}

}  // namespace d2gs
