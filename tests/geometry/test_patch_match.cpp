// PatchMatch multi-view stereo and its fusion: the plane / homography / NCC math against direct
// computations, depth and fused points against the synthetic scene's exact geometry, determinism, the
// no-test-image rule and the one-line errors of bad inputs.
#include <gtest/gtest.h>

#include <omp.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <set>

#include <fmt/format.h>

#include "d2gs/core/error.hpp"
#include "d2gs/core/random.hpp"
#include "d2gs/demo/synthetic_scene.hpp"
#include "d2gs/geometry/fusion.hpp"
#include "d2gs/geometry/patch_match.hpp"
#include "d2gs/geometry/patch_match_fusion.hpp"
#include "d2gs/geometry/training_geometry.hpp"
#include "d2gs/scene/split.hpp"
#include "synthetic_fixture.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {
namespace fs = std::filesystem;

const SyntheticScene& scene() { return test::small_synthetic_scene(); }

glm::dvec2 project(const Camera& c, const glm::dvec3& X) {
  const glm::dvec3 q = c.R_world_to_cam * X + c.t_world_to_cam;
  return {c.fx * q.x / q.z + c.cx, c.fy * q.y / q.z + c.cy};
}

TEST(PatchMatchMath, PlaneHomographyMapsPlanePointsToTheirProjections) {
  const auto& cams = scene().cameras();
  const Camera &ref = cams[1], &src = cams[12];
  Rng rng(5);
  for (int trial = 0; trial < 20; ++trial) {
    const int x = 20 + static_cast<int>(rng.below(200)), y = 20 + static_cast<int>(rng.below(150));
    const double z = 2.0 + 30.0 * rng.uniform();
    glm::dvec3 n(rng.normal() * 0.4, rng.normal() * 0.4, -1.0);
    n = glm::normalize(n);
    const glm::dmat3 H = plane_homography(ref, src, x, y, z, n);
    // Another pixel of the reference: its point on the plane, projected directly into the source.
    const int x2 = x + static_cast<int>(rng.below(11)) - 5, y2 = y + static_cast<int>(rng.below(11)) - 5;
    const double z2 = plane_depth_at(ref, x, y, z, n, x2, y2);
    const glm::dvec3 X2 = backproject(ref, x2, y2, z2);
    const glm::dvec2 direct = project(src, X2);
    const glm::dvec3 h = H * glm::dvec3(x2 + 0.5, y2 + 0.5, 1.0);
    EXPECT_NEAR(h.x / h.z, direct.x, 1e-6 * std::max(1.0, std::abs(direct.x)));
    EXPECT_NEAR(h.y / h.z, direct.y, 1e-6 * std::max(1.0, std::abs(direct.y)));
  }
}

TEST(PatchMatchMath, PlaneDepthTransferStaysOnThePlane) {
  const Camera& c = scene().cameras()[4];
  const glm::dvec3 n = glm::normalize(glm::dvec3(0.3, -0.2, -1.0));
  const double z1 = 7.0;
  const glm::dvec3 r1((10 + 0.5 - c.cx) / c.fx, (20 + 0.5 - c.cy) / c.fy, 1.0);
  const double z2 = plane_depth_at(c, 10, 20, z1, n, 60, 90);
  const glm::dvec3 r2((60 + 0.5 - c.cx) / c.fx, (90 + 0.5 - c.cy) / c.fy, 1.0);
  EXPECT_NEAR(glm::dot(n, z2 * r2 - z1 * r1), 0.0, 1e-9);
  EXPECT_NE(z2, z1);  // a slanted plane: the depth changes
  // A fronto-parallel plane keeps its depth.
  EXPECT_NEAR(plane_depth_at(c, 10, 20, z1, glm::dvec3(0, 0, -1), 60, 90), z1, 1e-12);
}

// The bilateral NCC written out in double precision, as the header states it.
double direct_ncc_cost(const Image& ref, const Image& src, const glm::dmat3& H, int x, int y, int radius, int step,
                       double ss, double sc) {
  const double centre = ref.at(x, y, 0);
  double sw = 0, sr = 0, sq = 0, srr = 0, sqq = 0, srq = 0;
  for (int dy = -radius; dy <= radius; dy += step)
    for (int dx = -radius; dx <= radius; dx += step) {
      const double r = ref.at(x + dx, y + dy, 0);
      const glm::dvec3 h = H * glm::dvec3(x + dx + 0.5, y + dy + 0.5, 1.0);
      const double u = h.x / h.z - 0.5, v = h.y / h.z - 0.5;
      const int iu = static_cast<int>(std::floor(u)), iv = static_cast<int>(std::floor(v));
      const double fu = u - iu, fv = v - iv;
      const double q = (1 - fv) * ((1 - fu) * src.at(iu, iv, 0) + fu * src.at(iu + 1, iv, 0)) +
                       fv * ((1 - fu) * src.at(iu, iv + 1, 0) + fu * src.at(iu + 1, iv + 1, 0));
      const double w = std::exp(-(dx * dx + dy * dy) / (2 * ss * ss) - (r - centre) * (r - centre) / (2 * sc * sc));
      sw += w, sr += w * r, sq += w * q, srr += w * r * r, sqq += w * q * q, srq += w * r * q;
    }
  const double mr = sr / sw, mq = sq / sw;
  const double vr = srr / sw - mr * mr, vq = sqq / sw - mq * mq, cov = srq / sw - mr * mq;
  if (vr < 1e-5 || vq < 1e-5) return 2.0;  // a window without texture: the maximum (COLMAP's threshold)
  return 1.0 - cov / std::sqrt(vr * vq);
}

TEST(PatchMatchMath, BilateralNccMatchesTheDirectFormula) {
  const auto& cams = scene().cameras();
  const Image ref = to_grey(scene().render(cams[1])), src = to_grey(scene().render(cams[12]));
  Rng rng(9);
  int textured = 0;
  for (int trial = 0; trial < 20; ++trial) {
    const int x = 30 + static_cast<int>(rng.below(190)), y = 30 + static_cast<int>(rng.below(130));
    const glm::dvec3 n = glm::normalize(glm::dvec3(0.1 * rng.normal(), 0.1 * rng.normal(), -1.0));
    const glm::dmat3 H = plane_homography(cams[1], cams[12], x, y, 3.0 + 10.0 * rng.uniform(), n);
    const glm::dvec3 h = H * glm::dvec3(x + 0.5, y + 0.5, 1.0);
    if (h.x / h.z < 10 || h.y / h.z < 10 || h.x / h.z > 240 || h.y / h.z > 178) continue;  // window inside
    for (int step : {1, 2}) {
      const double fast = bilateral_ncc_cost(ref, src, H, x, y, 5, step, 5.0, 0.2);
      const double direct = direct_ncc_cost(ref, src, H, x, y, 5, step, 5.0, 0.2);
      EXPECT_NEAR(fast, direct, 2e-3) << x << "," << y << " step " << step;
      textured += direct < 2.0;
    }
  }
  EXPECT_GT(textured, 5);  // the comparison was not only of textureless windows
  // Invariances: an affine change of the intensities costs nothing; the negative image costs the maximum.
  Image affine = ref, negative = ref;
  for (auto& v : affine.pixels) v = 0.5f * v + 0.2f;
  for (auto& v : negative.pixels) v = 1.0f - v;
  const glm::dmat3 I(1.0);
  EXPECT_NEAR(bilateral_ncc_cost(ref, affine, I, 100, 80, 5, 1, 5.0, 0.2), 0.0, 1e-3);
  EXPECT_NEAR(bilateral_ncc_cost(ref, negative, I, 100, 80, 5, 1, 5.0, 0.2), 2.0, 1e-3);
  // No texture in the source window: the maximum cost.
  EXPECT_EQ(bilateral_ncc_cost(ref, Image(ref.width, ref.height, 1, 0.5f), I, 100, 80, 5, 1, 5.0, 0.2), 2.0);
}

// The stereo scores many (plane, source) pairs of a pixel side by side (SIMD lanes where the CPU has AVX2):
// every cost must equal the one-pair function's bit for bit (the stereo's output is compared byte for byte
// across versions), lanes that leave their image and pixels at the border included.
TEST(PatchMatchMath, BatchedNccCostsEqualTheSinglePairBitForBit) {
  const auto& cams = scene().cameras();
  const Image ref = to_grey(scene().render(cams[1]));
  const Image src_a = to_grey(scene().render(cams[12])), src_b = to_grey(scene().render(cams[5]));
  Rng rng(17);
  int compared = 0, finite = 0, maximal = 0;
  for (int trial = 0; trial < 40; ++trial) {
    // Interior pixels, and some within the window radius of the border.
    const int x = trial % 5 == 0 ? static_cast<int>(rng.below(4)) : static_cast<int>(rng.below(static_cast<std::uint64_t>(ref.width)));
    const int y = trial % 7 == 0 ? ref.height - 1 - static_cast<int>(rng.below(4))
                                 : static_cast<int>(rng.below(static_cast<std::uint64_t>(ref.height)));
    std::vector<const Image*> sources;
    std::vector<glm::dmat3> Hs;
    const int pairs = 1 + static_cast<int>(rng.below(30));  // partial and several SIMD groups
    for (int k = 0; k < pairs; ++k) {
      const bool a = rng.uniform() < 0.5;
      const glm::dvec3 n = glm::normalize(glm::dvec3(0.3 * rng.normal(), 0.3 * rng.normal(), -1.0));
      sources.push_back(a ? &src_a : &src_b);
      Hs.push_back(plane_homography(cams[1], cams[a ? 12 : 5], x, y, 2.0 + 15.0 * rng.uniform(), n));
    }
    for (int step : {1, 2}) {
      const auto batched = bilateral_ncc_costs(ref, sources, Hs, x, y, 5, step, 5.0, 0.2);
      ASSERT_EQ(batched.size(), sources.size());
      for (std::size_t k = 0; k < sources.size(); ++k) {
        const double single = bilateral_ncc_cost(ref, *sources[k], Hs[k], x, y, 5, step, 5.0, 0.2);
        EXPECT_EQ(std::bit_cast<std::uint64_t>(batched[k]), std::bit_cast<std::uint64_t>(single))
            << x << "," << y << " pair " << k << ": " << batched[k] << " vs " << single;
        ++compared;
        finite += single < 2.0;
        maximal += single == 2.0;
      }
    }
  }
  EXPECT_GT(compared, 400);
  EXPECT_GT(finite, 100);  // real NCC values were compared
  EXPECT_GT(maximal, 10);  // and lanes that left the source image
}

// Three views of the synthetic scene (a wide triangle of the camera grid) with their exact depth maps.
struct ThreeViews {
  std::vector<Camera> cams;
  std::vector<Image> images;
  std::vector<std::vector<float>> truth;
  std::vector<std::pair<double, double>> ranges;
  std::vector<const Camera*> cam_ptrs() const {
    std::vector<const Camera*> p;
    for (const auto& c : cams) p.push_back(&c);
    return p;
  }
  std::vector<const Image*> image_ptrs() const {
    std::vector<const Image*> p;
    for (const auto& i : images) p.push_back(&i);
    return p;
  }
};

const ThreeViews& three_views() {
  static const ThreeViews t = [] {
    ThreeViews v;
    for (int i : {1, 3, 12}) {
      v.cams.push_back(scene().cameras()[static_cast<std::size_t>(i)]);
      v.images.push_back(scene().render(v.cams.back()));
      v.truth.push_back(scene().depth_map(v.cams.back()));
      v.ranges.emplace_back(2.0, 45.0);  // the scene's near surfaces to beyond its backdrop
    }
    return v;
  }();
  return t;
}

PatchMatchOptions quick_options() {
  PatchMatchOptions o;
  o.seed = 1;
  return o;
}

// Depth errors as disparity errors in pixels against the nearest other view, f·B·|1/z − 1/z_true|: the unit
// in which stereo errs (a tenth of a pixel is 4 % of depth on the far backdrop, 0.2 % up close).
struct DepthStats {
  double valid = 0, median_px = 1e9, within_half_px = 0;
};

DepthStats depth_stats(const DepthMap& d, const std::vector<float>& truth, std::size_t view) {
  const auto& cams = three_views().cams;
  double baseline = 1e9;
  for (std::size_t j = 0; j < cams.size(); ++j)
    if (j != view) baseline = std::min(baseline, glm::length(cams[j].center_world() - cams[view].center_world()));
  const double fB = cams[view].fx * baseline;
  std::vector<double> err;
  std::size_t close = 0;
  for (std::size_t i = 0; i < truth.size(); ++i)
    if (d.depth[i] > 0.0f) {
      const double e = fB * std::abs(1.0 / d.depth[i] - 1.0 / truth[i]);
      err.push_back(e);
      close += e < 0.5;
    }
  DepthStats s;
  if (err.empty()) return s;
  std::sort(err.begin(), err.end());
  s.valid = static_cast<double>(err.size()) / static_cast<double>(truth.size());
  s.median_px = err[err.size() / 2];
  s.within_half_px = static_cast<double>(close) / static_cast<double>(err.size());
  return s;
}

const std::vector<PatchMatchMap>& synthetic_maps() {
  static const auto maps = patch_match_stereo(three_views().cam_ptrs(), three_views().image_ptrs(),
                                              three_views().ranges, quick_options());
  return maps;
}

TEST(PatchMatch, SyntheticDepthMapsRecoverTheTrueDepth) {
  const auto& maps = synthetic_maps();
  ASSERT_EQ(maps.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    const DepthStats s = depth_stats(maps[i].depth, three_views().truth[i], i);
    std::printf("patch match, view %s: %.1f %% kept, median disparity error %.3f px, %.1f %% within 0.5 px\n",
                three_views().cams[i].image_name.c_str(), 100 * s.valid, s.median_px, 100 * s.within_half_px);
    EXPECT_GT(s.valid, 0.3);
    EXPECT_LT(s.median_px, 0.25);
    EXPECT_GT(s.within_half_px, 0.7);
    // Kept pixels carry unit normals facing the camera.
    const Camera& c = three_views().cams[i];
    for (int y = 0; y < c.height; y += 7)
      for (int x = 0; x < c.width; x += 7) {
        const std::size_t p = static_cast<std::size_t>(y) * c.width + x;
        if (!(maps[i].depth.depth[p] > 0.0f)) continue;
        const glm::vec3 n = maps[i].normals[p];
        ASSERT_NEAR(glm::length(n), 1.0f, 1e-4f);
        ASSERT_LT(glm::dot(n, glm::vec3((x + 0.5 - c.cx) / c.fx, (y + 0.5 - c.cy) / c.fy, 1.0)), 0.0f);
      }
  }
  // The filter and the geometric stage matter: without them more pixels are kept, and they are worse.
  PatchMatchOptions raw = quick_options();
  raw.filter_min_consistent = 0;
  raw.geometric_iterations = 0;
  const auto unfiltered = patch_match_stereo(three_views().cam_ptrs(), three_views().image_ptrs(), three_views().ranges, raw);
  const DepthStats f = depth_stats(maps[0].depth, three_views().truth[0], 0);
  const DepthStats u = depth_stats(unfiltered[0].depth, three_views().truth[0], 0);
  std::printf("unfiltered: %.1f %% kept, %.1f %% within 0.5 px\n", 100 * u.valid, 100 * u.within_half_px);
  EXPECT_GT(u.valid, f.valid);
  EXPECT_LT(u.within_half_px, f.within_half_px);
}

TEST(PatchMatch, FusedCloudLiesOnTheTrueSurfaces) {
  const auto& v = three_views();
  PatchMatchFusionOptions fo;
  fo.pixel_stride = 1;
  const PointCloud cloud = fuse_patch_match(v.cam_ptrs(), v.image_ptrs(), synthetic_maps(), fo);
  ASSERT_EQ(cloud.normals.size(), cloud.size());
  // Each point against the traced surface along its ray from the first view, as a disparity error (px)
  // against its nearest other view.
  const Camera& c = v.cams[0];
  const double fB = c.fx * std::min(glm::length(v.cams[1].center_world() - c.center_world()),
                                    glm::length(v.cams[2].center_world() - c.center_world()));
  std::vector<double> rel;
  std::size_t normal_ok = 0;
  for (std::size_t k = 0; k < cloud.size(); ++k) {
    const glm::dvec3 X(cloud.positions[k]);
    const glm::dvec3 q = c.R_world_to_cam * X + c.t_world_to_cam;
    const glm::dvec2 u = project(c, X);
    if (!(q.z > 0) || u.x < 0 || u.y < 0 || u.x >= c.width || u.y >= c.height) continue;
    const SyntheticHit hit = scene().trace(c, u.x, u.y);
    rel.push_back(fB * std::abs(1.0 / q.z - 1.0 / hit.depth));
    normal_ok += glm::dot(glm::dvec3(cloud.normals[k]), hit.normal) > std::cos(glm::radians(20.0));
  }
  ASSERT_GT(rel.size(), 5000u);
  std::sort(rel.begin(), rel.end());
  const double median = rel[rel.size() / 2], p90 = rel[rel.size() * 9 / 10];
  std::printf("fused: %zu points, median disparity error %.3f px, 90th percentile %.3f px, normals within 20°: %.1f %%\n",
              cloud.size(), median, p90, 100.0 * static_cast<double>(normal_ok) / static_cast<double>(rel.size()));
  EXPECT_LT(median, 0.2);
  EXPECT_LT(p90, 1.0);
  // The default has no normal test (patch_match_fusion.hpp): the normals are means of whatever joined.
  EXPECT_GT(static_cast<double>(normal_ok) / static_cast<double>(rel.size()), 0.5);
  // COLMAP's 10° normal test keeps fewer points, with normals closer to the surface's.
  {
    PatchMatchFusionOptions strict = fo;
    strict.max_normal_deg = 10.0;
    const PointCloud s10 = fuse_patch_match(v.cam_ptrs(), v.image_ptrs(), synthetic_maps(), strict);
    std::size_t inside = 0, ok10 = 0;
    for (std::size_t k = 0; k < s10.size(); ++k) {
      const glm::dvec2 u = project(c, glm::dvec3(s10.positions[k]));
      if (u.x < 0 || u.y < 0 || u.x >= c.width || u.y >= c.height) continue;
      ++inside;
      ok10 += glm::dot(glm::dvec3(s10.normals[k]), scene().trace(c, u.x, u.y).normal) > std::cos(glm::radians(20.0));
    }
    std::printf("fused with the 10° normal test: %zu points, normals within 20°: %.1f %%\n", s10.size(),
                100.0 * static_cast<double>(ok10) / static_cast<double>(inside));
    EXPECT_LT(s10.size(), cloud.size());
    EXPECT_GT(static_cast<double>(ok10) / static_cast<double>(inside), 0.6);
    EXPECT_GT(static_cast<double>(ok10) / static_cast<double>(inside),
              static_cast<double>(normal_ok) / static_cast<double>(rel.size()));
  }
  // The stride keeps about 1/stride² of the points; a higher pixel minimum keeps fewer.
  fo.pixel_stride = 4;
  const std::size_t strided = fuse_patch_match(v.cam_ptrs(), v.image_ptrs(), synthetic_maps(), fo).size();
  EXPECT_NEAR(static_cast<double>(strided), static_cast<double>(cloud.size()) / 16.0, 0.25 * cloud.size() / 16.0);
  fo.pixel_stride = 1;
  fo.min_pixels = 3;
  EXPECT_LT(fuse_patch_match(v.cam_ptrs(), v.image_ptrs(), synthetic_maps(), fo).size(), cloud.size());
}

TEST(PatchMatchFusion, ExactMapsFuseOntoTheSurfaceAndWrongOnesDoNot) {
  const auto& v = three_views();
  std::vector<PatchMatchMap> maps(3);
  for (std::size_t i = 0; i < 3; ++i) {
    const Camera& c = v.cams[i];
    maps[i].depth = DepthMap{c.width, c.height, v.truth[i]};
    maps[i].normals.resize(v.truth[i].size());
    for (int y = 0; y < c.height; ++y)
      for (int x = 0; x < c.width; ++x)
        maps[i].normals[static_cast<std::size_t>(y) * c.width + x] =
            glm::vec3(c.R_world_to_cam * scene().trace(c, x + 0.5, y + 0.5).normal);
  }
  // View 0's depths 5 % too far: they agree with no other view, so its pixels fuse with nothing.
  for (auto& d : maps[0].depth.depth) d *= 1.05f;
  PatchMatchFusionOptions fo;
  fo.pixel_stride = 1;
  const PointCloud cloud = fuse_patch_match(v.cam_ptrs(), v.image_ptrs(), maps, fo);
  const Camera& c = v.cams[1];
  std::size_t on_surface = 0;
  for (const auto& p : cloud.positions) {
    const glm::dvec3 q = c.R_world_to_cam * glm::dvec3(p) + c.t_world_to_cam;
    const glm::dvec2 u = project(c, glm::dvec3(p));
    if (u.x < 0 || u.y < 0 || u.x >= c.width || u.y >= c.height) continue;
    on_surface += std::abs(q.z - scene().trace(c, u.x, u.y).depth) < 0.005 * q.z;
  }
  EXPECT_GT(cloud.size(), 20000u);
  EXPECT_GT(static_cast<double>(on_surface) / static_cast<double>(cloud.size()), 0.95);
  // Only views 1 and 2 agree: no point has more than two pixels... except through chains; none from view 0.
  fo.min_pixels = 3;
  const std::size_t three = fuse_patch_match(v.cam_ptrs(), v.image_ptrs(), maps, fo).size();
  EXPECT_LT(three, cloud.size() / 5);
  fo.min_pixels = 0;
  EXPECT_THROW(fuse_patch_match(v.cam_ptrs(), v.image_ptrs(), maps, fo), Error);
}

// The colour test: points on the true surface, coloured by the images, pass; points in mid-air in front of
// it, coloured by the first view's pixel behind them (what a wrong but multi-view-consistent depth gives),
// are seen through by the other views to a different colour and go; a point that the other views' surfaces
// hide is judged only where it is visible.
TEST(PatchMatchFusion, ColourTestDropsMidAirPointsAndKeepsTheSurface) {
  const auto& v = three_views();
  std::vector<DepthMap> truth;
  std::vector<const DepthMap*> depths;
  for (std::size_t i = 0; i < 3; ++i) truth.push_back(DepthMap{v.cams[i].width, v.cams[i].height, v.truth[i]});
  for (const auto& d : truth) depths.push_back(&d);
  const Camera& c = v.cams[0];
  const Image& im = v.images[0];
  PointCloud cloud;
  std::size_t surface = 0;
  Rng rng = Rng::stream(7, "colour-test");
  auto add = [&](int x, int y, double depth_scale) {
    const double z = v.truth[0][static_cast<std::size_t>(y) * c.width + x];
    if (!(z > 0)) return false;
    cloud.positions.emplace_back(glm::vec3(backproject(c, x, y, z * depth_scale)));
    glm::u8vec3 rgb;
    for (int k = 0; k < 3; ++k)
      rgb[k] = static_cast<std::uint8_t>(std::lround(std::clamp(double(im.at(x, y, std::min(k, im.channels - 1))), 0.0, 1.0) * 255));
    cloud.colors.push_back(rgb);
    return true;
  };
  for (int i = 0; i < 3000; ++i)
    surface += add(static_cast<int>(rng.below(static_cast<std::uint64_t>(c.width))),
                   static_cast<int>(rng.below(static_cast<std::uint64_t>(c.height))), 1.0);
  std::size_t floaters = 0;
  for (int i = 0; i < 3000; ++i)
    floaters += add(static_cast<int>(rng.below(static_cast<std::uint64_t>(c.width))),
                    static_cast<int>(rng.below(static_cast<std::uint64_t>(c.height))), 0.6);
  ASSERT_GT(surface, 2500u);
  ASSERT_GT(floaters, 2500u);
  PointCloud filtered = cloud;
  const std::size_t dropped = drop_color_disagreeing_points(filtered, v.cam_ptrs(), v.image_ptrs(), depths, 0.10, 1.03);
  ASSERT_EQ(filtered.size() + dropped, cloud.size());
  // Which survived (the order is kept): the first `surface` points are the surface's.
  std::size_t surface_kept = 0, floaters_kept = 0, j = 0;
  for (std::size_t k = 0; k < cloud.size() && j < filtered.size(); ++k)
    if (cloud.positions[k] == filtered.positions[j]) {
      (k < surface ? surface_kept : floaters_kept) += 1;
      ++j;
    }
  ASSERT_EQ(j, filtered.size());
  const double surface_frac = double(surface_kept) / double(surface), floater_frac = double(floaters_kept) / double(floaters);
  std::printf("colour test at 0.10: %.1f %% of surface points kept, %.1f %% of mid-air points kept\n",
              100 * surface_frac, 100 * floater_frac);
  // The synthetic textures change colour at the pixel scale (checker edges, speckle), so a surface point
  // whose projection lands across an edge in another view can fail the test: about a tenth do. Half of the
  // mid-air points land on a like colour (the backdrop's broad patches, the ground's cells) and stay.
  EXPECT_GT(surface_frac, 0.85);
  EXPECT_LT(floater_frac, 0.6);
  EXPECT_GT(1.0 - floater_frac, 4.0 * (1.0 - surface_frac));
  // Off: nothing goes; same input, same output whatever the thread count.
  PointCloud off = cloud;
  EXPECT_EQ(drop_color_disagreeing_points(off, v.cam_ptrs(), v.image_ptrs(), depths, 0.0, 1.03), 0u);
  EXPECT_EQ(off.size(), cloud.size());
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  PointCloud one = cloud;
  drop_color_disagreeing_points(one, v.cam_ptrs(), v.image_ptrs(), depths, 0.10, 1.03);
  omp_set_num_threads(threads);
  EXPECT_EQ(one.positions, filtered.positions);
  // A point behind the surface in every view is judged by none, whatever its colour; the same point, with
  // a visibility margin that no longer hides it, is judged and goes.
  PointCloud hidden;
  for (int y = c.height / 4; y < c.height && hidden.empty(); y += 7)
    for (int x = c.width / 4; x < c.width && hidden.empty(); x += 7) {
      const double z = v.truth[0][static_cast<std::size_t>(y) * c.width + x];
      if (!(z > 0)) continue;
      const glm::dvec3 X = backproject(c, x, y, z * 1.3);
      bool hidden_everywhere = true;
      for (std::size_t i = 0; i < 3; ++i) {
        const Camera& ci = v.cams[i];
        const glm::dvec3 q = ci.R_world_to_cam * X + ci.t_world_to_cam;
        const glm::dvec2 u = project(ci, X);
        const bool inside = q.z > 0 && u.x >= 0 && u.y >= 0 && u.x < ci.width && u.y < ci.height;
        const double d = inside ? truth[i].at(static_cast<int>(u.x), static_cast<int>(u.y)) : 0.0;
        hidden_everywhere = hidden_everywhere && inside && d > 0 && q.z > 1.1 * d;
      }
      if (!hidden_everywhere) continue;
      glm::u8vec3 wrong;
      for (int k = 0; k < 3; ++k) wrong[k] = im.at(x, y, std::min(k, im.channels - 1)) > 0.5f ? 0 : 255;
      hidden.positions.emplace_back(glm::vec3(X));
      hidden.colors.push_back(wrong);
    }
  ASSERT_EQ(hidden.size(), 1u);
  PointCloud seen = hidden;
  EXPECT_EQ(drop_color_disagreeing_points(hidden, v.cam_ptrs(), v.image_ptrs(), depths, 0.10, 1.03), 0u);
  EXPECT_EQ(drop_color_disagreeing_points(seen, v.cam_ptrs(), v.image_ptrs(), depths, 0.10, 2.0), 1u);
  // Fusion with the test on gives a subset of the cloud without it, and says how many it removed.
  PatchMatchFusionOptions fo;
  EXPECT_EQ(fo.max_color_difference, 0.10);  // on by default
  fo.max_color_difference = 0.0;
  fo.pixel_stride = 2;
  PatchMatchFusionStats stats;
  const PointCloud plain = fuse_patch_match(v.cam_ptrs(), v.image_ptrs(), synthetic_maps(), fo, &stats);
  EXPECT_EQ(stats.fused, plain.size());
  EXPECT_EQ(stats.color_dropped, 0u);
  fo.max_color_difference = 0.10;
  const PointCloud tested = fuse_patch_match(v.cam_ptrs(), v.image_ptrs(), synthetic_maps(), fo, &stats);
  EXPECT_EQ(stats.fused, plain.size());
  EXPECT_EQ(tested.size() + stats.color_dropped, plain.size());
  EXPECT_LT(stats.color_dropped, plain.size() / 10);  // a good cloud loses little
  fo.max_color_difference = 1.5;
  EXPECT_THROW(validate(fo), Error);
  fo.max_color_difference = -0.1;
  EXPECT_THROW(validate(fo), Error);
}

TEST(PatchMatch, SameSeedSameMapsWhateverTheThreadCount) {
  const auto& v = three_views();
  PatchMatchOptions o = quick_options();
  o.iterations = 2;
  o.geometric_iterations = 1;
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const auto one = patch_match_stereo(v.cam_ptrs(), v.image_ptrs(), v.ranges, o);
  omp_set_num_threads(2);
  const auto two = patch_match_stereo(v.cam_ptrs(), v.image_ptrs(), v.ranges, o);
  omp_set_num_threads(threads);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(one[i].depth.depth, two[i].depth.depth);
    EXPECT_TRUE(one[i].normals == two[i].normals);
  }
  o.seed = 2;
  const auto other = patch_match_stereo(v.cam_ptrs(), v.image_ptrs(), v.ranges, o);
  EXPECT_NE(other[0].depth.depth, one[0].depth.depth);
}

TEST(PatchMatch, BadInputsGiveOneLineErrors) {
  const auto& v = three_views();
  const auto expect_error = [](auto&& f, const std::string& part) {
    try {
      f();
      ADD_FAILURE() << "expected an error containing " << part;
    } catch (const Error& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find(part), std::string::npos) << m;
      EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    }
  };
  // A view without texture.
  std::vector<Image> images = v.images;
  images[1] = Image(images[1].width, images[1].height, 3, 0.4f);
  std::vector<const Image*> ptrs = {&images[0], &images[1], &images[2]};
  expect_error([&] { (void)patch_match_stereo(v.cam_ptrs(), ptrs, v.ranges, quick_options()); },
               v.cams[1].image_name + ": the image has no texture");
  // A bad depth range, a wrong image size, a bad option.
  auto ranges = v.ranges;
  ranges[2] = {5.0, 1.0};
  expect_error([&] { (void)patch_match_stereo(v.cam_ptrs(), v.image_ptrs(), ranges, quick_options()); },
               "invalid depth range");
  std::vector<const Image*> small = {&v.images[0], &v.images[1], &images[0]};
  Image tiny(10, 10, 3);
  small[2] = &tiny;
  expect_error([&] { (void)patch_match_stereo(v.cam_ptrs(), small, v.ranges, quick_options()); }, "image is 10x10");
  PatchMatchOptions bad = quick_options();
  bad.window_radius = 30;
  expect_error([&] { (void)patch_match_stereo(v.cam_ptrs(), v.image_ptrs(), v.ranges, bad); }, "window radius");
  bad = quick_options();
  bad.filter_min_triangulation_angle_deg = -1.0;
  expect_error([&] { (void)patch_match_stereo(v.cam_ptrs(), v.image_ptrs(), v.ranges, bad); },
               "smallest triangulation angle must be in [0, 90) degrees, got -1");
  bad = quick_options();
  bad.filter_geom_max_px = 0.0;
  expect_error([&] { (void)patch_match_stereo(v.cam_ptrs(), v.image_ptrs(), v.ranges, bad); },
               "largest forward-backward error must be positive, got 0 px");
  bad = quick_options();
  bad.filter_min_ncc = 1.5;
  expect_error([&] { (void)patch_match_stereo(v.cam_ptrs(), v.image_ptrs(), v.ranges, bad); },
               "smallest NCC must be in [-1, 1], got 1.5");
  bad = quick_options();
  bad.filter_min_distinctiveness = -0.1;
  expect_error([&] { (void)patch_match_stereo(v.cam_ptrs(), v.image_ptrs(), v.ranges, bad); },
               "smallest distinctiveness must be in [0, 2], got -0.1");
  bad = quick_options();
  bad.filter_distinct_shift_px = 0.0;
  expect_error([&] { (void)patch_match_stereo(v.cam_ptrs(), v.image_ptrs(), v.ranges, bad); },
               "distinctiveness shift must be in (0, 100] px, got 0");
  bad = quick_options();
  bad.filter_distinct_aperture = true;
  expect_error([&] { (void)patch_match_stereo(v.cam_ptrs(), v.image_ptrs(), v.ranges, bad); },
               "aperture mode of the distinctiveness test needs its threshold");
  bad = quick_options();
  bad.filter_min_uniqueness = 2.5;
  expect_error([&] { (void)patch_match_stereo(v.cam_ptrs(), v.image_ptrs(), v.ranges, bad); },
               "smallest uniqueness must be in [0, 2], got 2.5");
  bad = quick_options();
  bad.filter_uniqueness_step = 0.0;
  expect_error([&] { (void)patch_match_stereo(v.cam_ptrs(), v.image_ptrs(), v.ranges, bad); },
               "uniqueness test's step must be in [0.05, 4] window radii, got 0");
}

// The filter's triangulation angle (d2gs init --pm-filter-min-angle): 0 keeps every depth the sources
// confirm, a larger angle only removes depths, and an angle wider than the views' own rejects them all.
TEST(PatchMatch, FilterAngleOnlyRemovesDepths) {
  const auto& v = three_views();
  const auto valid = [&](double angle) {
    PatchMatchOptions o = quick_options();
    o.levels = 1, o.iterations = 1, o.fine_iterations = 0, o.geometric_iterations = 0;  // the filter is what counts
    o.filter_min_triangulation_angle_deg = angle;
    std::vector<std::size_t> counts;
    for (const auto& m : patch_match_stereo(v.cam_ptrs(), v.image_ptrs(), v.ranges, o))
      counts.push_back(m.depth.valid_count());
    return counts;
  };
  const auto none = valid(0.0), some = valid(3.0), all = valid(89.0);
  for (std::size_t i = 0; i < none.size(); ++i) {
    EXPECT_GT(none[i], 0u) << i;
    EXPECT_LE(some[i], none[i]) << i;
    EXPECT_EQ(all[i], 0u) << i;
  }
}

// Two cameras with a horizontal baseline (centres at x = 0 and 0.8, f = 150 px, 160×120) looking at the
// fronto-parallel plane z = 10 painted with texture(X, Y): the scene of the distinctiveness tests.
struct PlanePair {
  static constexpr int W = 160, H = 120;
  static constexpr double kPlaneZ = 10.0;
  std::vector<Camera> cams = std::vector<Camera>(2);
  std::vector<Image> images;
  std::vector<std::pair<double, double>> ranges = std::vector<std::pair<double, double>>(2, {5.0, 20.0});

  template <class Texture> explicit PlanePair(const Texture& texture) {
    for (int k = 0; k < 2; ++k) {
      Camera& c = cams[static_cast<std::size_t>(k)];
      c.image_name = fmt::format("view{}", k);
      c.width = W, c.height = H, c.fx = c.fy = 150.0, c.cx = W / 2.0, c.cy = H / 2.0;
      c.t_world_to_cam = glm::dvec3(-0.8 * k, 0.0, 0.0);
      Image im(W, H, 3);
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
          const double X = (x + 0.5 - c.cx) / c.fx * kPlaneZ + 0.8 * k, Y = (y + 0.5 - c.cy) / c.fy * kPlaneZ;
          for (int ch = 0; ch < 3; ++ch) im.at(x, y, ch) = static_cast<float>(texture(X, Y));
        }
      images.push_back(std::move(im));
    }
  }
  std::vector<PatchMatchMap> stereo(const PatchMatchOptions& o) const {
    return patch_match_stereo({&cams[0], &cams[1]}, {&images[0], &images[1]}, ranges, o);
  }
  // The maps without the distinctiveness test, with it (T = 0.1, S = 5 px) and in its aperture mode.
  struct Modes {
    std::vector<PatchMatchMap> off, on, aperture;
  };
  Modes distinctiveness_modes() const {
    PatchMatchOptions o = quick_options();
    o.levels = 1, o.iterations = 4, o.fine_iterations = 0;
    Modes m;
    m.off = stereo(o);
    o.filter_min_distinctiveness = 0.1;
    m.on = stereo(o);
    o.filter_distinct_aperture = true;
    m.aperture = stereo(o);
    return m;
  }
  // Depths of view 0 kept in columns [x0, x1) and rows [y0, y1); `accurate`: those within 0.5 px of disparity.
  static std::size_t kept(const PatchMatchMap& m, int x0, int x1, int y0, int y1, std::size_t& accurate) {
    std::size_t n = 0;
    accurate = 0;
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) {
        const float z = m.depth.depth[static_cast<std::size_t>(y) * W + x];
        if (!(z > 0.0f)) continue;
        ++n;
        accurate += std::abs(150.0 * 0.8 * (1.0 / z - 1.0 / kPlaneZ)) < 0.5;
      }
    return n;
  }
};

// Value noise on a 0.15-unit grid (about 2 px at the plane's depth), in [0.15, 0.85].
struct ValueNoise {
  static constexpr int G = 64;
  std::vector<double> grid = std::vector<double>(G * G);
  explicit ValueNoise(std::uint64_t seed) {
    Rng rng(seed);
    for (auto& g : grid) g = rng.uniform();
  }
  double operator()(double X, double Y) const {
    const double gx = std::clamp(X / 0.15 + 4.0, 0.0, G - 1.001), gy = std::clamp(Y / 0.15 + G / 2.0, 0.0, G - 1.001);
    const int ix = static_cast<int>(gx), iy = static_cast<int>(gy);
    const double fx = gx - ix, fy = gy - iy;
    const auto at = [&](int x, int y) { return grid[static_cast<std::size_t>(y) * G + x]; };
    return 0.15 + 0.7 * ((1 - fy) * ((1 - fx) * at(ix, iy) + fx * at(ix + 1, iy)) +
                         fy * ((1 - fx) * at(ix, iy + 1) + fx * at(ix + 1, iy + 1)));
  }
};

// The distinctiveness test (d2gs init --pm-filter-min-distinctiveness): the plane's left half has horizontal
// stripes (intensity varies with height only: every depth matches along the horizontal epipolar lines), its
// right half a 2D texture. With the test, the stripes keep (almost) no depth and the texture keeps most of
// its depths; off, it changes nothing. The aperture mode judges the stripes the same way: they have
// structure across the epipolar line.
TEST(PatchMatch, DistinctivenessDropsDepthsThatTheEpipolarLineDoesNotDetermine) {
  constexpr int H = PlanePair::H;
  const ValueNoise noise(7);
  const PlanePair scene([&](double X, double Y) { return X < 0.0 ? 0.5 + 0.35 * std::sin(2.0 * M_PI * Y / 0.4) : noise(X, Y); });
  const auto [off, on, aperture] = scene.distinctiveness_modes();
  // The reference view 0: world X = (x + 0.5 − 80)/15; stripes left of x ≈ 75, texture right of it; a margin
  // of a window (5 px) and of the other view's overlap (12 px of disparity at the right edge) apart.
  std::size_t acc_off_stripes, acc_on_stripes, acc_ap_stripes, acc_off_texture, acc_on_texture, acc_ap_texture;
  const std::size_t off_stripes = PlanePair::kept(off[0], 8, 68, 8, H - 8, acc_off_stripes),
                    on_stripes = PlanePair::kept(on[0], 8, 68, 8, H - 8, acc_on_stripes),
                    ap_stripes = PlanePair::kept(aperture[0], 8, 68, 8, H - 8, acc_ap_stripes);
  const std::size_t off_texture = PlanePair::kept(off[0], 84, 140, 8, H - 8, acc_off_texture),
                    on_texture = PlanePair::kept(on[0], 84, 140, 8, H - 8, acc_on_texture),
                    ap_texture = PlanePair::kept(aperture[0], 84, 140, 8, H - 8, acc_ap_texture);
  const std::size_t stripes_area = 60 * (H - 16), texture_area = 56 * (H - 16);
  std::printf("distinctiveness: stripes %zu -> %zu kept, aperture %zu (%zu, %zu, %zu within 0.5 px), texture %zu -> "
              "%zu, aperture %zu (%zu, %zu, %zu) of %zu, %zu px\n",
              off_stripes, on_stripes, ap_stripes, acc_off_stripes, acc_on_stripes, acc_ap_stripes, off_texture,
              on_texture, ap_texture, acc_off_texture, acc_on_texture, acc_ap_texture, stripes_area, texture_area);
  // Without the test the stripes keep depths, most of them wrong: the cameras cannot tell them apart.
  EXPECT_GT(off_stripes, stripes_area / 10);
  EXPECT_LT(acc_off_stripes, off_stripes / 2);
  // With it they keep almost none, and the texture keeps most of its (right) depths.
  EXPECT_LT(on_stripes, stripes_area / 100);
  EXPECT_LT(ap_stripes, stripes_area / 100);
  EXPECT_GT(off_texture, texture_area / 2);
  EXPECT_GT(on_texture, off_texture * 8 / 10);
  EXPECT_GT(acc_on_texture, on_texture * 9 / 10);
  EXPECT_GE(ap_texture, on_texture);
  // It only removes depths: every kept depth is the one kept without it.
  for (const auto* m : {&on, &aperture})
    for (std::size_t p = 0; p < off[0].depth.depth.size(); ++p) {
      if ((*m)[0].depth.depth[p] > 0.0f) {
        ASSERT_EQ((*m)[0].depth.depth[p], off[0].depth.depth[p]) << p;
      }
    }
}

// The aperture mode (--pm-filter-distinct-aperture): the plane's left half is shaded smoothly (intensity
// linear in X: a window shifted any way along or across the horizontal epipolar lines is the same window
// plus a constant, NCC 1), its right half textured. The plain test drops whatever depths the shading kept,
// the aperture mode keeps exactly the depths kept without the test there (flat in every direction: the
// plane is propagation's), and both keep the texture.
TEST(PatchMatch, DistinctivenessApertureModeKeepsWindowsFlatInEveryDirection) {
  constexpr int H = PlanePair::H;
  const ValueNoise noise(11);
  const PlanePair scene([&](double X, double Y) { return X < 0.0 ? 0.8 + 0.1 * X : noise(X, Y); });
  const auto [off, on, aperture] = scene.distinctiveness_modes();
  std::size_t a0, a1, a2, t0, t1, t2;
  const std::size_t off_shade = PlanePair::kept(off[0], 8, 68, 8, H - 8, a0), on_shade = PlanePair::kept(on[0], 8, 68, 8, H - 8, a1),
                    ap_shade = PlanePair::kept(aperture[0], 8, 68, 8, H - 8, a2);
  const std::size_t off_texture = PlanePair::kept(off[0], 84, 140, 8, H - 8, t0),
                    on_texture = PlanePair::kept(on[0], 84, 140, 8, H - 8, t1),
                    ap_texture = PlanePair::kept(aperture[0], 84, 140, 8, H - 8, t2);
  std::printf("aperture: shading %zu -> %zu kept, aperture %zu; texture %zu -> %zu, aperture %zu\n", off_shade, on_shade,
              ap_shade, off_texture, on_texture, ap_texture);
  EXPECT_GT(off_shade, std::size_t{100});
  EXPECT_LT(on_shade, off_shade / 10);
  EXPECT_EQ(ap_shade, off_shade);
  EXPECT_GT(on_texture, off_texture * 8 / 10);
  EXPECT_GE(ap_texture, on_texture);
}

// The uniqueness test (d2gs init --pm-filter-min-uniqueness): vertical stripes of period 40 px (intensity
// periodic in X, along the horizontal epipolar lines) over the whole plane, and a depth range (2 to 40:
// disparities 3 to 60 px, the plane at 12) that holds a second match of every window one period away (52 px),
// far beyond two window radii: the cameras cannot tell the two apart (PatchMatch happens to settle on the
// right one), and the test drops most of the depths. On a 2D texture with the same range it keeps most
// depths. It only removes depths. (The period is wide because the line is sampled about every window radius:
// a rival match narrower than that can fall between two samples, and some stripe windows near the
// sine's extremes keep their depth that way.)
TEST(PatchMatch, UniquenessDropsDepthsThatARepeatedPatternLeavesAmbiguous) {
  constexpr int H = PlanePair::H;
  constexpr double kPeriod = 40.0 / 15.0;  // 40 px at the plane's depth (15 px per unit)
  const auto maps = [](const PlanePair& scene, double unique, double step = 1.0) {
    PatchMatchOptions o = quick_options();
    o.levels = 1, o.iterations = 4, o.fine_iterations = 0;
    o.filter_min_uniqueness = unique;
    o.filter_uniqueness_step = step;
    return scene.stereo(o);
  };
  PlanePair stripes([&](double X, double) { return 0.5 + 0.35 * std::sin(2.0 * M_PI * X / kPeriod); });
  const ValueNoise noise(5);
  PlanePair texture([&](double X, double Y) { return noise(X, Y); });
  stripes.ranges.assign(2, {2.0, 40.0});
  texture.ranges.assign(2, {2.0, 40.0});
  const auto off = maps(stripes, 0.0), on = maps(stripes, 0.1), fine = maps(stripes, 0.1, 0.25);
  const auto t_off = maps(texture, 0.0), t_on = maps(texture, 0.1), t_fine = maps(texture, 0.1, 0.25);
  // Columns [64, 150) of view 0: both matches (12 and 52 px to the left) lie inside view 1 with a window.
  std::size_t a_off, a_on, a_t_off, a_t_on;
  const std::size_t n_off = PlanePair::kept(off[0], 64, 150, 8, H - 8, a_off),
                    n_on = PlanePair::kept(on[0], 64, 150, 8, H - 8, a_on),
                    n_t_off = PlanePair::kept(t_off[0], 64, 150, 8, H - 8, a_t_off),
                    n_t_on = PlanePair::kept(t_on[0], 64, 150, 8, H - 8, a_t_on);
  const std::size_t area = 86 * (H - 16);
  std::printf("uniqueness: stripes %zu kept (%zu within 0.5 px) -> %zu (%zu); texture %zu (%zu) -> %zu (%zu), of %zu px\n",
              n_off, a_off, n_on, a_on, n_t_off, a_t_off, n_t_on, a_t_on, area);
  // Without the test the stripes keep their depths; with it they lose most of them, and the texture keeps
  // most of its depths, nearly all of them right.
  EXPECT_GT(n_off, area / 2);
  EXPECT_LT(n_on, n_off / 4);
  EXPECT_GT(n_t_off, area / 2);
  EXPECT_GT(n_t_on, n_t_off * 8 / 10);
  EXPECT_GT(a_t_on, n_t_on * 9 / 10);
  // A search four times finer (--pm-filter-uniqueness-step 0.25) finds the rivals the coarse one stepped over,
  // and still keeps the texture's depths.
  std::size_t a_fine, a_t_fine;
  const std::size_t n_fine = PlanePair::kept(fine[0], 64, 150, 8, H - 8, a_fine),
                    n_t_fine = PlanePair::kept(t_fine[0], 64, 150, 8, H - 8, a_t_fine);
  std::printf("uniqueness, a quarter radius apart: stripes %zu kept, texture %zu (%zu)\n", n_fine, n_t_fine, a_t_fine);
  EXPECT_LT(n_fine, n_on / 2);
  EXPECT_GT(n_t_fine, n_t_off * 8 / 10);
  // Every filtered map keeps only depths of the unfiltered one.
  using Maps = decltype(off);
  const std::pair<const Maps*, const Maps*> filtered[] = {{&on, &off}, {&fine, &off}, {&t_on, &t_off}};
  for (const auto& [m, unfiltered] : filtered)
    for (std::size_t p = 0; p < (*m)[0].depth.depth.size(); ++p)
      if ((*m)[0].depth.depth[p] > 0.0f) {
        ASSERT_EQ((*m)[0].depth.depth[p], (*unfiltered)[0].depth.depth[p]) << p;
      }
}

TEST(TrainingGeometry, PatchMatchPipelineReadsOnlyTrainingViewsAndLiesOnTheSurfaces) {
  // Trained at half resolution; PatchMatch runs at the folder's full resolution (images/, 252x189).
  SceneLoadOptions lo;
  lo.resolution = 2;
  const Scene s = load_scene(test::small_synthetic_dir(), lo);
  SplitOptions so;
  so.n_views = 3;
  const Split split = make_split(s, so);
  TrainingGeometryOptions o;
  o.dense_method = DenseMethod::PatchMatch;
  EXPECT_EQ(geometry_resolution(s, o), 1);
  TrainingGeometry g;
  std::set<fs::path> read;
  {
    test::ImageReads reads;
    g = build_training_geometry(s, split.train, o);
    read.insert(reads.paths.begin(), reads.paths.end());
    EXPECT_EQ(reads.paths.size(), 3u);
  }
  std::set<fs::path> train;
  for (int v : split.train) train.insert(test::small_synthetic_dir() / "images" / s.cameras[static_cast<std::size_t>(v)].image_name);
  std::set<fs::path> read_names;
  for (const auto& p : read) read_names.insert(test::small_synthetic_dir() / "images" / p.filename());
  EXPECT_EQ(read_names, train);
  for (int v : split.test) EXPECT_EQ(read_names.count(test::small_synthetic_dir() / "images" / s.cameras[static_cast<std::size_t>(v)].image_name), 0u);
  EXPECT_EQ(g.geometry_resolution, 1);
  ASSERT_EQ(g.depth.size(), 3u);
  EXPECT_EQ(g.depth[0].width, 252);
  EXPECT_EQ(g.dense.normals.size(), g.dense.size());
  // Fused points against the traced surface from the first training view (full-resolution camera).
  const Camera& c = scene().cameras()[static_cast<std::size_t>(split.train[0])];
  std::vector<double> rel;
  for (const auto& p : g.dense.positions) {
    const glm::dvec3 q = c.R_world_to_cam * glm::dvec3(p) + c.t_world_to_cam;
    const glm::dvec2 u = project(c, glm::dvec3(p));
    if (!(q.z > 0) || u.x < 0 || u.y < 0 || u.x >= c.width || u.y >= c.height) continue;
    rel.push_back(std::abs(q.z - scene().trace(c, u.x, u.y).depth) / q.z);
  }
  ASSERT_GT(rel.size(), 500u);
  std::sort(rel.begin(), rel.end());
  std::printf("pipeline: %zu sparse, %zu dense points; median relative depth error %.4f\n", g.sparse.size(),
              g.dense.size(), rel[rel.size() / 2]);
  // The defaults keep small-angle depths and skip the normal test (more coverage, a little less accuracy:
  // patch_match.hpp, patch_match_fusion.hpp); 1.2 % here, under 1 % with COLMAP's nominal 3° and 10°.
  EXPECT_LT(rel[rel.size() / 2], 0.015);
}

TEST(TrainingGeometry, GeometryResolutionFollowsTheMethodAndTheCap) {
  SceneLoadOptions lo;
  lo.resolution = 8;
  const Scene fern = load_scene(test::shared_data() / "nerf_llff_data/fern", lo);
  TrainingGeometryOptions o;
  EXPECT_EQ(geometry_resolution(fern, o), 8);  // SGBM: the training resolution
  o.dense_method = DenseMethod::PatchMatch;
  EXPECT_EQ(geometry_resolution(fern, o), 4);  // images_4/ (1008x756) is fern's largest folder here
  o.max_image_size = 800;
  EXPECT_EQ(geometry_resolution(fern, o), 8);
  o.resolution = GeometryResolution::Training;
  o.max_image_size = 1600;
  EXPECT_EQ(geometry_resolution(fern, o), 8);
  o.resolution = GeometryResolution::Highest;
  o.dense_method = DenseMethod::Sgbm;
  EXPECT_EQ(geometry_resolution(fern, o), 4);
  EXPECT_THROW(parse_dense_method("colmap"), Error);
  EXPECT_THROW(parse_geometry_resolution("full"), Error);
}

}  // namespace
}  // namespace d2gs
