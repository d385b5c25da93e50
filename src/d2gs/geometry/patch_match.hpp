#pragma once
// PatchMatch multi-view stereo on the CPU, in the spirit of COLMAP's (Schönberger et al., ECCV 2016) and
// of Gipuma / ACMH (Galliani et al. ICCV 2015; Xu & Tao CVPR 2019). Every training view is a reference
// view in turn; every pixel holds a plane hypothesis (camera-space depth z and a unit normal in the
// reference camera's frame, facing the camera). A hypothesis is scored against each source view (the
// other views) by the plane-induced homography and a bilaterally weighted NCC over a window; the
// per-source costs are combined with per-pixel view-selection weights. Hypotheses improve by red-black
// checkerboard propagation (ACMH's adaptive sampling: the cheapest neighbour of each of 8 regions) and
// by random refinement with perturbations that halve every iteration. A second, geometric stage adds
// λ·min(forward–backward reprojection error, max) against the other views' depth maps, and a filter
// keeps a depth only where enough source views agree photometrically and geometrically.
//
// Deterministic for a given seed whatever the thread count: each half-sweep updates the pixels of one
// colour from the other colour only, and every pixel draws from its own random stream (seed, view,
// pixel, iteration). No heap allocation per pixel.
#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include <glm/glm.hpp>

#include "d2gs/core/image.hpp"
#include "d2gs/geometry/stereo.hpp"
#include "d2gs/scene/camera.hpp"

namespace d2gs {

struct PatchMatchOptions {
  // Photometric cost: 1 − bilaterally weighted NCC over a (2r+1)² window sampled every `window_step`
  // pixels (COLMAP: r = 5, σ_spatial = r, σ_color = 0.2 on grey values in [0, 1]; step 2 is 4× faster).
  int window_radius = 5;
  int window_step = 2;
  double sigma_spatial = 0.0;  // ≤ 0: window_radius
  double sigma_color = 0.2;
  // View selection: source j weighs exp(−c_j²/(2·ncc_sigma²)) (c_j its cost under the pixel's current
  // hypothesis; COLMAP's NCC likelihood, σ 0.6), times COLMAP's triangulation-angle prior below
  // `min_triangulation_angle_deg`.
  double ncc_sigma = 0.6;
  double min_triangulation_angle_deg = 1.0;
  int max_source_views = 8;  // nearest camera centres
  // Coarse to fine: `levels` pyramid levels (each half the size of the next; 1 = full size only). The
  // coarsest level starts from random planes and runs `iterations` exploring iterations (each a red and
  // a black half-sweep over 8 neighbour regions, refinement and a random plane); every finer level
  // starts from the coarser planes and runs `fine_iterations` refining ones (4 nearest regions and
  // perturbations); then `geometric_iterations` refining ones of the geometric stage at full size. The
  // perturbation halves every iteration (COLMAP's schedule). (Letting the geometric iterations replace
  // the full-size photometric one saves a quarter of the time but doubled the synthetic scene's median
  // disparity error, 0.18 → 0.30 px.)
  int levels = 2;
  int iterations = 3;
  int fine_iterations = 1;
  int geometric_iterations = 1;
  // Geometric consistency (COLMAP): cost += λ·min(forward–backward reprojection error in px, max).
  double geom_weight = 0.3;
  double geom_max_px = 3.0;
  // Filter (COLMAP's, except min_consistent: with 3 views, 2 would keep only what all three see): a source
  // agrees when its NCC ≥ filter_min_ncc, the triangulation angle ≥ filter_min_triangulation_angle_deg and
  // the forward–backward error ≤ filter_geom_max_px; a depth is kept when ≥ filter_min_consistent agree
  // (0: no filter).
  // The angle: COLMAP's nominal 3° never fired in the COLMAP that made the published sparse-view clouds (its
  // viewing-angle cosine had the wrong sign until COLMAP 8ce44e9, 2026-02), and the far background, seen
  // at small angles, is what a sparse-view init needs most: on fern, 0° instead of 3° is worth 0.8 dB of
  // DropGaussian's test PSNR at iteration 2 000 (docs/benchmarks.md, "What the far background is worth").
  double filter_min_ncc = 0.1;
  double filter_min_triangulation_angle_deg = 0.0;
  double filter_geom_max_px = 1.0;
  int filter_min_consistent = 1;
  // Distinctiveness (ours, not COLMAP's; 0: off): a source agrees only if its cost rises by at least this
  // much (in 1 − NCC) when the match moves `filter_distinct_shift_px` pixels either way along the epipolar
  // line in that source (the plane moved along the pixel's ray, its normal kept). A window with no texture
  // across the epipolar line (a uniform surface, an edge parallel to the baseline) matches equally well at
  // neighbouring depths, so its depth is not determined by the images: the curvature confidence of stereo
  // matching (Hu & Mordohai, TPAMI 2012), evaluated on the final plane. The shift is the window's radius: a
  // window that still matches a radius away has no structure across the line at its own scale (at 2 px the
  // test also drops the faint, low-frequency texture of walls, whose planes propagation got right:
  // docs/benchmarks.md).
  double filter_min_distinctiveness = 0.0;
  double filter_distinct_shift_px = 5.0;
  // Aperture mode of the distinctiveness test: a source rejects an undetermined depth only when its window
  // has structure across the epipolar line, i.e. its cost also rises by at least filter_min_distinctiveness
  // when the match moves the same shift perpendicular to the line (an edge or bar parallel to the baseline:
  // the aperture problem). A window flat in every direction (a uniform or smoothly shaded wall, on which
  // NCC sees nothing at the window's scale) keeps the plane that propagation gave it.
  bool filter_distinct_aperture = false;
  // Uniqueness (ours, not COLMAP's; 0.1 by default, 0: off): a source agrees only if every other match on its epipolar line,
  // more than two window radii from the kept one, costs at least this much more (in 1 − NCC): the plane moved
  // along the pixel's ray, its normal kept, sampled uniformly in inverse depth over the view's depth range at
  // about one sample per window radius of the line by default (filter_uniqueness_step; a rival narrower than
  // the step can fall between two samples: a coarse search for the broad ambiguities that cost most). A match that a repeated pattern, a reflection over a
  // transmitted scene or a uniform region lets the source make elsewhere as well is not determined by the
  // images: the second-minimum confidence of stereo matching (the peak ratio of Hu & Mordohai, TPAMI 2012;
  // SGBM's uniqueness ratio), on the final plane. Where the distinctiveness test looks a radius either
  // side of the match, this one looks along the rest of the line. On by default since issue 22: DropGaussian,
  // three seeds, horns +0.75 dB, room −0.05, fern −0.08 (docs/benchmarks.md).
  double filter_min_uniqueness = 0.1;
  // The uniqueness test's sampling interval along the epipolar line, in window radii, in [0.05, 4]: 1 is the
  // default's one sample per radius; a finer step catches narrower rivals at proportionally more cost.
  double filter_uniqueness_step = 1.0;
  std::uint64_t seed = 0;
};

// Throws d2gs::Error naming the option when one is out of range.
void validate(const PatchMatchOptions& options);

// One view's result: camera-space depth (0 = filtered out), unit normals in the camera frame (0 where
// the depth is 0) and the mean over the sources of the photometric cost (1 − NCC) of the kept plane.
struct PatchMatchMap {
  DepthMap depth;
  std::vector<glm::vec3> normals;
  std::vector<float> cost;
};

// Depth and normal maps of every view. `depth_ranges[i]` = (near, far) of view i's camera z (e.g. from the
// sparse points); initial depths are uniform in inverse depth within it. All views must have images
// of their cameras' sizes. Throws (one line, naming the view) for a view without texture or a camera
// that shares its centre with every other view.
std::vector<PatchMatchMap> patch_match_stereo(const std::vector<const Camera*>& cameras,
                                              const std::vector<const Image*>& images,
                                              const std::vector<std::pair<double, double>>& depth_ranges,
                                              const PatchMatchOptions& options);

// ---- the math, exposed for tests ----

// Homography H (glm column-major, H[col][row]) of the plane {X : n·X = n·(z·ray(x, y))} given in the
// reference camera's frame by its unit normal `n` and the depth `z` at pixel centre (x, y) (integer index,
// centre at +0.5): a pixel centre u = (x + 0.5, y + 0.5, 1) of the reference maps to H·u ~ the source pixel
// position (Camera convention). Equals K_src (R + t·nᵀ/ρ) K_ref⁻¹ with (R, t) reference → source and
// ρ = n·X₀.
glm::dmat3 plane_homography(const Camera& ref, const Camera& src, int x, int y, double z, const glm::dvec3& n);

// Depth along the ray of pixel (x2, y2) of the plane through the point at depth z1 of pixel (x1, y1) with
// camera-frame normal n; z1 when the ray is (nearly) parallel to the plane.
double plane_depth_at(const Camera& camera, int x1, int y1, double z1, const glm::dvec3& n, int x2, int y2);

// 1 − bilaterally weighted NCC between the window of `ref` (grey, one channel) around pixel (x, y) and
// `src` (grey) sampled bilinearly at H·u; 2 (the maximum) when either window has no variance or a sample
// falls outside `src`. The reference is the direct formula: weights exp(−(dx²+dy²)/(2σs²) −
// (I − I_centre)²/(2σc²)), weighted means, variances and covariance.
double bilateral_ncc_cost(const Image& ref, const Image& src, const glm::dmat3& H, int x, int y, int radius, int step,
                          double sigma_spatial, double sigma_color);

// bilateral_ncc_cost of `ref` at (x, y) against sources[l] through homographies[l] for every l, computed
// as the stereo computes them (several pairs side by side in SIMD lanes where the CPU has AVX2); equal bit
// for bit to bilateral_ncc_cost. At most 192 pairs.
std::vector<double> bilateral_ncc_costs(const Image& ref, const std::vector<const Image*>& sources,
                                        const std::vector<glm::dmat3>& homographies, int x, int y, int radius, int step,
                                        double sigma_spatial, double sigma_color);

// Grey values in [0, 1] (0.299 R + 0.587 G + 0.114 B) of an RGB image; a one-channel image is copied.
Image to_grey(const Image& image);

}  // namespace d2gs
