// The built-in synthetic demo scene (src/d2gs/demo/synthetic_scene.hpp) and `d2gs demo`.
#include "d2gs/demo/synthetic_scene.hpp"

#include <gtest/gtest.h>
#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numeric>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/file_lock.hpp"
#include "d2gs/core/image.hpp"
#include "d2gs/core/npy.hpp"
#include "d2gs/model/ply.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/scene/split.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {
namespace fs = std::filesystem;
using glm::dvec3;
using test::scratch_dir;

// Small and quick, but with every feature of the real thing.
SyntheticSceneOptions small_options() {
  SyntheticSceneOptions o;
  o.width = 160;
  o.height = 120;
  o.views = 6;
  o.supersample = 2;
  o.points = 3000;
  o.seed = 7;
  o.focal = 0;  // default: 407.566 * 160 / 504
  return o;
}

// One scene written for the read-only tests of this file, per process (CTest runs tests in parallel
// processes), removed at exit.
const fs::path& shared_scene() {
  struct Shared {
    fs::path dir = fs::temp_directory_path() / "d2gs-tests" / fmt::format("synthetic-shared-{}", ::getpid());
    Shared() {
      fs::remove_all(dir);
      write_synthetic_scene(dir, small_options());
    }
    ~Shared() {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  };
  static const Shared shared;
  return shared.dir;
}

std::vector<fs::path> files_below(const fs::path& dir) {
  std::vector<fs::path> out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) out.push_back(fs::relative(e.path(), dir));
  std::sort(out.begin(), out.end());
  return out;
}

double median(std::vector<double> v) {
  if (v.empty()) return std::nan("");
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

dvec3 unproject(const Camera& c, double px, double py, double depth) {
  const dvec3 cam((px - c.cx) / c.fx * depth, (py - c.cy) / c.fy * depth, depth);
  return c.R_cam_to_world() * cam + c.center_world();
}

dvec3 to_camera(const Camera& c, const dvec3& world) { return c.R_world_to_cam * world + c.t_world_to_cam; }

// ---- layout and files ----------------------------------------------------------------------------

TEST(SyntheticScene, WritesTheLlffLayout) {
  const auto& dir = shared_scene();
  const auto o = small_options();
  std::vector<fs::path> expected = {"points3D.ply", "poses_bounds.npy", "scene.json"};
  for (int k = 0; k < o.views; ++k) {
    expected.push_back(fs::path("images") / fmt::format("image{:03d}.png", k));
    expected.push_back(fs::path("depth") / fmt::format("image{:03d}.npy", k));
  }
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(files_below(dir), expected);
  for (int k = 0; k < o.views; ++k) {
    const auto size = read_image_size(dir / "images" / fmt::format("image{:03d}.png", k));
    EXPECT_EQ(size.width, 160);
    EXPECT_EQ(size.height, 120);
    const auto depth = read_npy(dir / "depth" / fmt::format("image{:03d}.npy", k));
    EXPECT_EQ(depth.shape, (std::vector<std::size_t>{120, 160}));
  }
  const auto j = nlohmann::json::parse(read_file(dir / "scene.json"));
  EXPECT_EQ(j["generator"], kSyntheticSceneGenerator);
  EXPECT_EQ(j["seed"], 7);
  EXPECT_EQ(j["complete"], true);
  EXPECT_EQ(j["cameras"].size(), 6u);
  EXPECT_GE(j["objects"].size(), 8u);
  EXPECT_TRUE(is_synthetic_scene(dir));
}

TEST(SyntheticScene, DefaultsMatchLlffAtOneEighth) {
  const SyntheticSceneOptions o;
  EXPECT_EQ(o.width, 504);
  EXPECT_EQ(o.height, 378);
  EXPECT_GE(o.views, 20);
  const auto cams = synthetic_scene_cameras(o);
  ASSERT_EQ(cams.size(), static_cast<std::size_t>(o.views));
  for (const auto& c : cams) {
    EXPECT_NEAR(c.fx, 407.566, 1e-9);
    EXPECT_EQ(c.fx, c.fy);
    EXPECT_EQ(c.cx, 252.0);
    EXPECT_EQ(c.cy, 189.0);
    EXPECT_EQ(c.width, 504);
    EXPECT_EQ(c.height, 378);
  }
}

TEST(SyntheticScene, CamerasAreForwardFacingOnASmallGrid) {
  const auto cams = synthetic_scene_cameras(SyntheticSceneOptions{});
  dvec3 lo(1e9), hi(-1e9);
  for (std::size_t k = 0; k < cams.size(); ++k) {
    const auto& c = cams[k];
    EXPECT_EQ(c.image_name, fmt::format("image{:03d}.png", k));
    // Rotation is orthonormal and right-handed.
    const glm::dmat3 r = c.R_world_to_cam;
    const glm::dmat3 g = glm::transpose(r) * r;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) EXPECT_NEAR(g[a][b], a == b ? 1.0 : 0.0, 1e-12);
    EXPECT_NEAR(glm::determinant(r), 1.0, 1e-12);
    // Looks along +z within 10 degrees, image "down" along +y.
    const dvec3 forward = c.R_cam_to_world()[2];
    EXPECT_GT(forward.z, std::cos(10.0 * 3.14159265358979 / 180.0));
    EXPECT_GT(c.R_cam_to_world()[1].y, 0.98);
    lo = glm::min(lo, c.center_world());
    hi = glm::max(hi, c.center_world());
  }
  const dvec3 span = hi - lo;
  EXPECT_GT(span.x, 0.8);
  EXPECT_LT(span.x, 1.2);
  EXPECT_GT(span.y, 0.4);
  EXPECT_LT(span.y, 0.8);
  EXPECT_LT(span.z, 0.2);
}

TEST(SyntheticScene, PosesBoundsFollowTheLlffConvention) {
  const auto& dir = shared_scene();
  const SyntheticScene scene(small_options());
  const auto npy = read_npy(dir / "poses_bounds.npy");
  // float64, as LLFF's own files.
  EXPECT_NE(read_file(dir / "poses_bounds.npy").find("'descr': '<f8'"), std::string::npos);
  ASSERT_EQ(npy.shape, (std::vector<std::size_t>{6, 17}));
  for (std::size_t k = 0; k < 6; ++k) {
    const Camera& cam = scene.cameras()[k];
    const double* v = npy.values.data() + k * 17;
    // Independent decoding of SOURCES.md: row-major 3x5, columns [down, right, back, centre, hwf];
    // OpenCV camera-to-world = [col1, col0, -col2]; world-to-camera R = its transpose, t = -R centre.
    const auto col = [&](int c) { return dvec3(v[c], v[5 + c], v[10 + c]); };
    const glm::dmat3 c2w(col(1), col(0), -col(2));
    const glm::dmat3 r = glm::transpose(c2w);
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) EXPECT_NEAR(r[a][b], cam.R_world_to_cam[a][b], 1e-15);
    const dvec3 t = -(r * col(3));
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(t[a], cam.t_world_to_cam[a], 1e-12);
    EXPECT_EQ(v[4], 120.0);   // H
    EXPECT_EQ(v[9], 160.0);   // W
    EXPECT_EQ(v[14], cam.fx);  // f
    // near, far: the range of the view's true depth.
    const auto depth = read_npy(dir / "depth" / fmt::format("image{:03d}.npy", k));
    const auto [lo, hi] = std::minmax_element(depth.values.begin(), depth.values.end());
    EXPECT_EQ(v[15], *lo);
    EXPECT_EQ(v[16], *hi);
  }
}

TEST(SyntheticScene, LoadSceneReadsItWithTheSameCameras) {
  const auto& dir = shared_scene();
  const SyntheticScene truth(small_options());
  const Scene scene = load_scene(dir);
  EXPECT_EQ(scene.format, SceneFormat::Llff);
  ASSERT_EQ(scene.cameras.size(), truth.cameras().size());
  for (std::size_t k = 0; k < scene.cameras.size(); ++k) {
    const Camera& a = scene.cameras[k];
    const Camera& b = truth.cameras()[k];
    EXPECT_EQ(a.image_name, b.image_name);
    EXPECT_EQ(a.width, b.width);
    EXPECT_EQ(a.height, b.height);
    EXPECT_NEAR(a.fx, b.fx, 1e-12);
    EXPECT_NEAR(a.fy, b.fy, 1e-12);
    EXPECT_NEAR(a.cx, b.cx, 1e-12);
    EXPECT_NEAR(a.cy, b.cy, 1e-12);
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(a.t_world_to_cam[i], b.t_world_to_cam[i], 1e-12);
      for (int j = 0; j < 3; ++j) EXPECT_NEAR(a.R_world_to_cam[i][j], b.R_world_to_cam[i][j], 1e-12);
    }
  }
  EXPECT_TRUE(scene.warnings.empty());
  const Image first = load_image(scene, 0);
  EXPECT_EQ(first.width, 160);
  EXPECT_EQ(first.channels, 3);
}

// ---- geometry --------------------------------------------------------------------------------------

TEST(SyntheticScene, DepthMapIsTheTracedDepthAtPixelCentres) {
  const auto& dir = shared_scene();
  const SyntheticScene scene(small_options());
  for (int k : {0, 5}) {
    const Camera& cam = scene.cameras()[static_cast<std::size_t>(k)];
    const auto file = read_npy(dir / "depth" / fmt::format("image{:03d}.npy", k));
    const auto map = scene.depth_map(cam);  // screen-space culling inside must not change anything
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) {
        const auto i = static_cast<std::size_t>(y * cam.width + x);
        const float traced = static_cast<float>(scene.trace_depth(cam, x, y));
        ASSERT_EQ(map[i], traced) << x << "," << y;
        ASSERT_EQ(file.values[i], static_cast<double>(traced));
        const auto hit = scene.trace(cam, x + 0.5, y + 0.5);
        ASSERT_TRUE(hit.hit);
        // The hit lies on the ray at that view-space z.
        ASSERT_NEAR(to_camera(cam, hit.position).z, hit.depth, 1e-9 * hit.depth);
      }
  }
}

TEST(SyntheticScene, DepthIsConsistentAcrossViews) {
  const SyntheticScene scene(small_options());
  const auto& cams = scene.cameras();
  std::size_t visible = 0, occluded = 0, inside = 0;
  std::vector<double> errors;
  for (std::size_t a = 0; a < cams.size(); ++a) {
    const std::size_t b = (a + 3) % cams.size();
    const Camera& A = cams[a];
    const Camera& B = cams[b];
    for (int y = 1; y < A.height; y += 7)
      for (int x = 1; x < A.width; x += 7) {
        const dvec3 world = unproject(A, x + 0.5, y + 0.5, scene.trace_depth(A, x, y));
        const dvec3 pb = to_camera(B, world);
        ASSERT_GT(pb.z, 0.0);
        const double u = B.fx * pb.x / pb.z + B.cx, v = B.fy * pb.y / pb.z + B.cy;
        if (u < 0 || v < 0 || u >= B.width || v >= B.height) continue;
        ++inside;
        const auto hit = scene.trace(B, u, v);
        ASSERT_TRUE(hit.hit);
        // A ray towards a surface point cannot pass it: the first hit is at it or in front of it.
        ASSERT_LE(hit.depth, pb.z * (1 + 1e-7) + 1e-7) << "view " << a << " pixel " << x << "," << y;
        if (hit.depth > pb.z * (1 - 1e-7)) {
          ++visible;
          errors.push_back(std::abs(hit.depth - pb.z) / pb.z);
        } else {
          ++occluded;
        }
      }
  }
  EXPECT_GT(inside, 1000u);
  EXPECT_GT(visible, 0.75 * static_cast<double>(inside));  // mostly visible, some occlusion
  EXPECT_GT(occluded, 0u);
  EXPECT_LT(median(errors), 1e-12);
}

TEST(SyntheticScene, DepthMapFilesReprojectConsistently) {
  // The same check on the stored float32 maps at integer pixels: nearest-pixel lookups, so judged by
  // the median relative error among points that land on the same surface.
  const auto& dir = shared_scene();
  const SyntheticScene scene(small_options());
  const auto& cams = scene.cameras();
  const auto da = read_npy(dir / "depth" / "image001.npy");
  const auto db = read_npy(dir / "depth" / "image004.npy");
  const Camera& A = cams[1];
  const Camera& B = cams[4];
  std::vector<double> rel;
  for (int y = 0; y < A.height; y += 3)
    for (int x = 0; x < A.width; x += 3) {
      const double d = da.values[static_cast<std::size_t>(y * A.width + x)];
      const dvec3 pb = to_camera(B, unproject(A, x + 0.5, y + 0.5, d));
      const int u = static_cast<int>(std::floor(B.fx * pb.x / pb.z + B.cx));
      const int v = static_cast<int>(std::floor(B.fy * pb.y / pb.z + B.cy));
      if (u < 0 || v < 0 || u >= B.width || v >= B.height) continue;
      rel.push_back(std::abs(db.values[static_cast<std::size_t>(v * B.width + u)] - pb.z) / pb.z);
    }
  ASSERT_GT(rel.size(), 1000u);
  EXPECT_LT(median(rel), 0.01);
  std::sort(rel.begin(), rel.end());
  EXPECT_LT(rel[rel.size() * 3 / 4], 0.03);
}

TEST(SyntheticScene, HasANearAndAFarField) {
  const auto& dir = shared_scene();
  for (int k = 0; k < small_options().views; ++k) {
    const auto d = read_npy(dir / "depth" / fmt::format("image{:03d}.npy", k));
    const auto [lo, hi] = std::minmax_element(d.values.begin(), d.values.end());
    EXPECT_LT(*lo, 4.0) << k;
    EXPECT_GT(*hi, 30.0) << k;
    EXPECT_GT(*hi / *lo, 8.0) << k;
    // Both fields cover a real share of the image.
    const auto near = std::count_if(d.values.begin(), d.values.end(), [](double z) { return z < 6.0; });
    const auto far = std::count_if(d.values.begin(), d.values.end(), [](double z) { return z > 20.0; });
    EXPECT_GT(static_cast<double>(near) / static_cast<double>(d.size()), 0.1) << k;
    EXPECT_GT(static_cast<double>(far) / static_cast<double>(d.size()), 0.1) << k;
  }
}

TEST(SyntheticScene, PointsLieOnVisibleSurfacesWithTheImageColours) {
  const auto& dir = shared_scene();
  const SyntheticScene scene(small_options());
  const auto cloud = read_point_cloud_ply(dir / "points3D.ply");
  EXPECT_GE(cloud.size(), 2900u);
  EXPECT_LE(cloud.size(), 3100u);
  std::vector<Image> images;
  for (const auto& c : scene.cameras()) images.push_back(read_image(dir / c.image_path));
  std::size_t seen = 0, checked = 0;
  std::vector<double> colour_error;
  for (std::size_t i = 0; i < cloud.size(); i += 7) {
    ++checked;
    bool found = false;
    for (std::size_t k = 0; k < scene.cameras().size(); ++k) {
      const Camera& cam = scene.cameras()[k];
      const dvec3 p = to_camera(cam, dvec3(cloud.positions[i]));
      if (p.z <= 0) continue;
      const double u = cam.fx * p.x / p.z + cam.cx, v = cam.fy * p.y / p.z + cam.cy;
      if (u < 0 || v < 0 || u >= cam.width || v >= cam.height) continue;
      const auto hit = scene.trace(cam, u, v);
      if (std::abs(hit.depth - p.z) > 1e-5 * p.z) continue;  // occluded in this view
      found = true;
      const int x = static_cast<int>(u), y = static_cast<int>(v);
      double e = 0;
      for (int c = 0; c < 3; ++c) e += std::abs(images[k].at(x, y, c) - cloud.colors[i][c] / 255.0) / 3.0;
      colour_error.push_back(e);
    }
    if (found) ++seen;
  }
  // Every point is on a surface some camera sees (it was sampled from one) ...
  EXPECT_EQ(seen, checked);
  // ... and has roughly the colour of the pixel it lands in (pixels average a few samples; views differ
  // at texture and shadow edges).
  EXPECT_LT(median(colour_error), 0.06);
}

TEST(SyntheticScene, ImagesAreTexturedAndShaded) {
  const SyntheticScene scene(small_options());
  const Image im = scene.render(scene.cameras()[0]);
  ASSERT_EQ(im.width, 160);
  ASSERT_EQ(im.height, 120);
  // Values in [0, 1], plenty of distinct colours and strong local gradients (features for matching).
  std::size_t edges = 0;
  double lo = 1, hi = 0;
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x + 1 < im.width; ++x)
      for (int c = 0; c < 3; ++c) {
        const float v = im.at(x, y, c);
        ASSERT_GE(v, 0.0f);
        ASSERT_LE(v, 1.0f);
        lo = std::min(lo, static_cast<double>(v));
        hi = std::max(hi, static_cast<double>(v));
        if (std::abs(im.at(x + 1, y, c) - v) > 0.2f) ++edges;
      }
  EXPECT_LT(lo, 0.15);
  EXPECT_GT(hi, 0.8);
  EXPECT_GT(edges, 500u);
}

// ---- determinism -----------------------------------------------------------------------------------

TEST(SyntheticScene, SameSeedGivesIdenticalBytesWhateverTheThreadCount) {
  const auto dir = scratch_dir();
  auto o = small_options();
  o.views = 3;
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  write_synthetic_scene(dir / "a", o);
  omp_set_num_threads(std::max(2, threads));
  write_synthetic_scene(dir / "b", o);
  omp_set_num_threads(threads);
  const auto files = files_below(dir / "a");
  ASSERT_EQ(files, files_below(dir / "b"));
  ASSERT_EQ(files.size(), 9u);
  for (const auto& f : files) EXPECT_EQ(read_file(dir / "a" / f), read_file(dir / "b" / f)) << f;

  o.seed = 8;
  write_synthetic_scene(dir / "c", o);
  EXPECT_NE(read_file(dir / "a" / "images" / "image000.png"), read_file(dir / "c" / "images" / "image000.png"));
  EXPECT_NE(read_file(dir / "a" / "poses_bounds.npy"), read_file(dir / "c" / "poses_bounds.npy"));
}

// ---- never destroying user data --------------------------------------------------------------------

TEST(SyntheticScene, RefusesToOverwriteForeignData) {
  const auto dir = scratch_dir();
  auto o = small_options();
  o.views = 2;
  o.width = o.height = 32;
  // A folder with the user's files.
  write_file_atomic(dir / "mine" / "notes.txt", "precious");
  try {
    write_synthetic_scene(dir / "mine", o);
    ADD_FAILURE() << "overwrote a foreign folder";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("refusing"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find((dir / "mine").string()), std::string::npos) << e.what();
  }
  EXPECT_EQ(files_below(dir / "mine"), std::vector<fs::path>{"notes.txt"});
  EXPECT_EQ(read_file(dir / "mine" / "notes.txt"), "precious");
  // Someone else's scene.json.
  write_file_atomic(dir / "other" / "scene.json", R"({"generator": "blender"})");
  EXPECT_THROW(write_synthetic_scene(dir / "other", o), Error);
  write_file_atomic(dir / "broken" / "scene.json", "{not json");
  EXPECT_THROW(write_synthetic_scene(dir / "broken", o), Error);
  EXPECT_EQ(files_below(dir / "other"), std::vector<fs::path>{"scene.json"});
  // A file in place of the folder.
  write_file_atomic(dir / "file", "x");
  EXPECT_THROW(write_synthetic_scene(dir / "file", o), Error);
  EXPECT_EQ(read_file(dir / "file"), "x");
  // An empty folder is fine.
  fs::create_directories(dir / "empty");
  EXPECT_NO_THROW(write_synthetic_scene(dir / "empty", o));
  EXPECT_TRUE(is_synthetic_scene(dir / "empty"));
}

TEST(SyntheticScene, RewritesItsOwnSceneKeepingOtherFiles) {
  const auto dir = scratch_dir() / "scene";
  auto o = small_options();
  o.width = o.height = 32;
  o.views = 5;
  write_synthetic_scene(dir, o);
  write_file_atomic(dir / "train" / "model.ply", "user output");  // e.g. a later training run
  write_file_atomic(dir / "images" / ".image003.tmp999-1.png", "left by a killed run");
  o.views = 3;
  o.seed = 99;
  write_synthetic_scene(dir, o);
  std::vector<fs::path> expected = {"points3D.ply", "poses_bounds.npy", "scene.json", "train/model.ply"};
  for (int k = 0; k < 3; ++k) {
    expected.push_back(fs::path("images") / fmt::format("image{:03d}.png", k));
    expected.push_back(fs::path("depth") / fmt::format("image{:03d}.npy", k));
  }
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(files_below(dir), expected);
  EXPECT_EQ(read_file(dir / "train" / "model.ply"), "user output");
  EXPECT_EQ(nlohmann::json::parse(read_file(dir / "scene.json"))["seed"], 99);
  EXPECT_EQ(load_scene(dir).cameras.size(), 3u);
  // A rewrite that fails part-way (here a folder stands where view 1's depth map goes) leaves no poses: the
  // folder of old and new views is no scene until a rewrite completes.
  o.seed = 7;
  fs::remove(dir / "depth" / "image001.npy");
  fs::create_directories(dir / "depth" / "image001.npy" / "in the way");
  EXPECT_THROW(write_synthetic_scene(dir, o), Error);
  EXPECT_FALSE(fs::exists(dir / "poses_bounds.npy"));
  EXPECT_THROW(load_scene(dir), Error);
  fs::remove_all(dir / "depth" / "image001.npy");
  write_synthetic_scene(dir, o);
  EXPECT_EQ(load_scene(dir).cameras.size(), 3u);
}

// A progress callback that throws (an interruption, a closed terminal) ends the write with its error, from
// whichever view's thread called it: no exception may leave the OpenMP section the callback runs in.
TEST(SyntheticScene, AProgressCallbackThatThrowsEndsTheWriteWithItsError) {
  const auto dir = scratch_dir() / "scene";
  auto o = small_options();
  o.width = o.height = 32;
  o.views = 6;
  int calls = 0;
  try {
    write_synthetic_scene(dir, o, [&](int done, int) {
      ++calls;
      if (done == 2) fail("progress failed at view {}", done);
    });
    ADD_FAILURE() << "the callback's error was lost";
  } catch (const Error& e) {
    EXPECT_STREQ(e.what(), "progress failed at view 2");
  }
  EXPECT_GE(calls, 2);
  EXPECT_FALSE(fs::exists(dir / "poses_bounds.npy"));  // not a loadable scene
  write_synthetic_scene(dir, o);
  EXPECT_EQ(load_scene(dir).cameras.size(), 6u);
}

TEST(SyntheticScene, RejectsBadOptions) {
  const auto dir = scratch_dir();
  const auto bad = [&](auto edit, const char* needle) {
    auto o = small_options();
    edit(o);
    try {
      write_synthetic_scene(dir / "x", o);
      ADD_FAILURE() << needle;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  bad([](auto& o) { o.views = 1; }, "views");
  bad([](auto& o) { o.width = 0; }, "width");
  bad([](auto& o) { o.height = 100000; }, "height");
  bad([](auto& o) { o.supersample = 0; }, "supersample");
  bad([](auto& o) { o.focal = -1; }, "focal");
  bad([](auto& o) { o.points = -5; }, "points");
  EXPECT_FALSE(fs::exists(dir / "x"));
}

// ---- the command -----------------------------------------------------------------------------------

TEST(DemoCommand, GeneratesTheSceneAndSaysWhatNext) {
  const auto dir = scratch_dir() / "my demo";
  const auto r = test::run_cli(fmt::format("demo -o '{}' --views 3 --seed 5 --scene-only", dir.string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find(dir.string()), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("Next: d2gs info"), std::string::npos) << r.output;
  const auto j = nlohmann::json::parse(read_file(dir / "scene.json"));
  EXPECT_EQ(j["seed"], 5);
  EXPECT_EQ(j["views"], 3);
  const auto size = read_image_size(dir / "images" / "image002.png");
  EXPECT_EQ(size.width, 504);
  EXPECT_EQ(size.height, 378);
  // The suggested next command works on it.
  const auto info = test::run_cli(fmt::format("info -s '{}'", dir.string()));
  EXPECT_EQ(info.exit_code, 0) << info.output;

  write_file_atomic(dir.parent_path() / "user" / "a.txt", "x");
  const auto refused = test::run_cli(fmt::format("demo -o '{}'", (dir.parent_path() / "user").string()));
  EXPECT_EQ(refused.exit_code, 1) << refused.output;
  EXPECT_NE(refused.output.find("d2gs: error:"), std::string::npos) << refused.output;
  EXPECT_NE(refused.output.find("refusing"), std::string::npos) << refused.output;
  const auto bad = test::run_cli(fmt::format("demo -o '{}' --views 1", (dir.parent_path() / "v").string()));
  EXPECT_NE(bad.exit_code, 0);
}

// The whole demo on a small schedule: scene, initial points from the training views only (first the
// default, the estimated geometry of d2gs init; then the true depth of the training views), D²GS training,
// evaluation and the report, whose path it prints. Run twice into the same folder: the second replaces the
// first demo's run.
TEST(DemoCommand, TrainsEvaluatesAndWritesTheReport) {
  const auto dir = scratch_dir() / "demo";
  for (int attempt = 0; attempt < 2; ++attempt) {
    const std::string init = attempt == 0 ? "" : " --init training-depth";
    const auto r = test::run_cli(fmt::format("demo -o '{}' --views 9 -r 8 --iterations 12{}", dir.string(), init));
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const auto run_config = nlohmann::json::parse(read_file(dir / "run" / "config.json"));
    if (attempt == 0) {
      // The trainer ran the geometry of the training images itself and cached it in the run folder.
      EXPECT_EQ(run_config["init"], "dense");
      EXPECT_EQ(run_config["init_is_oracle"], false);
      EXPECT_TRUE(fs::is_directory(dir / "run" / "init")) << r.output;
    } else {
      EXPECT_EQ(run_config["init"], (dir / "init_training_views.ply").string());
    }
    const auto report = dir / "run" / "report.html";
    EXPECT_NE(r.output.find("Report: " + report.string()), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("Held-out views: PSNR"), std::string::npos) << r.output;
    ASSERT_TRUE(fs::is_regular_file(report));
    const std::string html = read_file(report);
    for (const char* id : {"metrics", "curves", "views", "layers"})
      EXPECT_NE(html.find(std::string("<section id=\"") + id + "\">"), std::string::npos) << id;
    const auto results = nlohmann::json::parse(read_file(dir / "run" / "results.json"));
    EXPECT_EQ(results["iteration"], 12);
    EXPECT_EQ(results["per_view"].size(), 2u);  // images 0 and 8
  }
  // The initial cloud comes from the 3 training views only: about 10 000 points, each of which lies at
  // the true depth of some training view's pixel.
  const PointCloud init = read_point_cloud_ply(dir / "init_training_views.ply");
  EXPECT_GT(init.size(), 8000u);
  EXPECT_LT(init.size(), 12000u);
  const Scene scene = load_scene(dir);
  SplitOptions so;
  so.n_views = 3;
  const Split split = make_split(scene, so);
  std::vector<NpyArray> depth;
  for (int v : split.train) depth.push_back(read_npy(dir / "depth" / fmt::format("image{:03d}.npy", v)));
  std::size_t on_surface = 0;
  for (const auto& p : init.positions) {
    bool hit = false;
    for (std::size_t k = 0; k < split.train.size() && !hit; ++k) {
      const Camera& cam = scene.cameras[static_cast<std::size_t>(split.train[k])];
      const glm::dvec3 c = cam.R_world_to_cam * glm::dvec3(p) + cam.t_world_to_cam;
      if (c.z <= 0) continue;
      const int x = static_cast<int>(std::floor(cam.fx * c.x / c.z + cam.cx));
      const int y = static_cast<int>(std::floor(cam.fy * c.y / c.z + cam.cy));
      if (x < 0 || y < 0 || x >= cam.width || y >= cam.height) continue;
      const double d = depth[k].values[static_cast<std::size_t>(y) * cam.width + x];
      hit = std::abs(d - c.z) < 1e-4 * c.z;
    }
    on_surface += hit ? 1 : 0;
  }
  EXPECT_EQ(on_surface, init.size());
  const auto config = nlohmann::json::parse(read_file(dir / "run" / "config.json"));
  EXPECT_EQ(config["method"], "d2gs");
  EXPECT_EQ(config["n_views"], 3);
}

// `demo --views 3` leaves 2 non-test views for 3 training views: it used to fail only after rendering and
// writing the whole scene.
TEST(DemoCli, ImpossibleSplitFailsBeforeTheSceneIsWritten) {
  const auto dir = test::scratch_dir();
  const auto r = test::run_cli(fmt::format("demo -o '{}' --views 3", (dir / "demo").string()));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("--views 3 with --n-views 3"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "demo")) << r.output;
  // --scene-only needs no split.
  const auto only = test::run_cli(fmt::format("-q demo -o '{}' --views 3 --scene-only", (dir / "scene").string()));
  EXPECT_EQ(only.exit_code, 0) << only.output;
}

// While one demo writes into a folder (its lock held here), a second one there writes nothing and says
// who holds it; a folder holding only the lock file counts as empty for the scene.
TEST(DemoCli, OneDemoAtATimeIntoAFolder) {
  const auto dir = test::scratch_dir() / "demo";
  fs::create_directories(dir);
  {
    const auto held = FileLock::try_acquire(dir / kSyntheticSceneLock);
    ASSERT_TRUE(held);
    const auto busy = test::run_cli(fmt::format("demo -o '{}' --views 9 -r 8 --iterations 2 --init random", dir.string()));
    EXPECT_EQ(busy.exit_code, 1) << busy.output;
    EXPECT_NE(busy.output.find(dir.string() + ": another d2gs demo (process " + std::to_string(::getpid()) +
                               ") is writing into this folder"),
              std::string::npos)
        << busy.output;
    EXPECT_EQ(files_below(dir), std::vector<fs::path>{kSyntheticSceneLock});  // nothing else was written
  }
  // The lock file of a demo killed before it removed it does not make the folder foreign.
  write_file_atomic(dir / kSyntheticSceneLock, "12345\n");
  const auto ok = test::run_cli(fmt::format("-q demo -o '{}' --views 9 --scene-only", dir.string()));
  ASSERT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_TRUE(is_synthetic_scene(dir));
  EXPECT_FALSE(fs::exists(dir / kSyntheticSceneLock));  // removed by the demo that held it
}

// OUTPUT/run is the demo's to replace only when a demo marked it so: a run of the user's there was deleted.
TEST(DemoCli, ReplacesOnlyARunAnEarlierDemoWrote) {
  const auto dir = test::scratch_dir() / "scene";
  ASSERT_EQ(test::run_cli(fmt::format("-q demo -o '{}' --views 9 --scene-only", dir.string())).exit_code, 0);
  const std::string scene_json = read_file(dir / "scene.json");
  fs::create_directories(dir / "run");
  write_file_atomic(dir / "run/config.json", R"({"method": "dropgaussian"})");
  write_file_atomic(dir / "run/NOTES.txt", "mine");
  const auto r = test::run_cli(fmt::format("demo -o '{}' --views 9 -r 8 --iterations 2 --init random", dir.string()));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find((dir / "run").string() + ": holds files the demo did not write"), std::string::npos) << r.output;
  EXPECT_EQ(read_file(dir / "run/NOTES.txt"), "mine");
  EXPECT_EQ(read_file(dir / "scene.json"), scene_json);
  fs::remove_all(dir / "run");
  write_file_atomic(dir / "run", "a file");
  const auto file = test::run_cli(fmt::format("demo -o '{}' --views 9 -r 8 --iterations 2 --init random", dir.string()));
  EXPECT_EQ(file.exit_code, 1) << file.output;
  EXPECT_NE(file.output.find("exists and is not a folder"), std::string::npos) << file.output;
  fs::remove(dir / "run");
  // The demo's own run is replaced by the next demo.
  for (int k = 0; k < 2; ++k) {
    const auto ok = test::run_cli(fmt::format("-q demo -o '{}' --views 9 -r 8 --iterations 2 --init random", dir.string()));
    ASSERT_EQ(ok.exit_code, 0) << ok.output;
    EXPECT_TRUE(fs::exists(dir / "run/.d2gs-demo-run"));
  }
}

}  // namespace
}  // namespace d2gs
