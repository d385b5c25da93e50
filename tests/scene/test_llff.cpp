// LLFF scenes (fern): poses_bounds.npy conventions, resolution folders and resampling, bad input.
#include <gtest/gtest.h>

#include <cmath>

#include "d2gs/core/image.hpp"
#include "d2gs/core/npy.hpp"
#include "d2gs/core/resize_pil.hpp"
#include "d2gs/scene/colmap.hpp"
#include "d2gs/scene/llff.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/scene/split.hpp"
#include "scene_test_util.hpp"

namespace d2gs {
namespace {

namespace fs = std::filesystem;
using test::expect_error;

using test::res;

TEST(Llff, FernAtOneEighth) {
  const Scene s = load_scene(test::fern_dir(), res(8));
  EXPECT_EQ(s.format, SceneFormat::Llff);
  EXPECT_EQ(s.images_folder, "images_8");
  ASSERT_EQ(s.cameras.size(), 20u);
  EXPECT_EQ(s.sfm_points.size(), 10091u);
  EXPECT_TRUE(s.warnings.empty());
  const auto raw = read_npy(test::fern_dir() / "poses_bounds.npy");
  for (std::size_t k = 0; k < 20; ++k) {
    const Camera& c = s.cameras[k];
    EXPECT_EQ(c.image_name, fmt::format("image{:03d}.png", k));
    EXPECT_EQ(c.width, 504);
    EXPECT_EQ(c.height, 378);
    EXPECT_EQ(c.resample_factor, 1);
    EXPECT_NEAR(c.fx, 407.566, 1e-3);  // SOURCES.md: f/8 = 407.566
    EXPECT_EQ(c.fx, c.fy);
    EXPECT_EQ(c.cx, 252.0);
    EXPECT_EQ(c.cy, 189.0);
    // The centre is column 3 of the row; the camera's right (+x) is column 1, down (+y) column 0,
    // forward (+z) minus column 2.
    const double* v = raw.values.data() + k * 17;
    const glm::dvec3 centre = c.center_world();
    EXPECT_NEAR(centre.x, v[3], 1e-9);
    EXPECT_NEAR(centre.y, v[8], 1e-9);
    EXPECT_NEAR(centre.z, v[13], 1e-9);
    const glm::dmat3 c2w = c.R_cam_to_world();
    for (int r = 0; r < 3; ++r) {
      EXPECT_NEAR(c2w[0][r], v[r * 5 + 1], 1e-12);
      EXPECT_NEAR(c2w[1][r], v[r * 5 + 0], 1e-12);
      EXPECT_NEAR(c2w[2][r], -v[r * 5 + 2], 1e-12);
    }
    EXPECT_NEAR(glm::determinant(c.R_world_to_cam), 1.0, 1e-6);
  }
}

TEST(Llff, FernPointsAreInFrontOfEveryCameraAndTracksLandInside) {
  // SOURCES.md: every point of points3D.bin projects in front of every camera, and each track
  // observation lands inside its image (image id k + 1 is the k-th image in name order).
  const Scene s = load_scene(test::fern_dir(), res(8));
  for (const Camera& c : s.cameras)
    for (const auto& p : s.sfm_points.positions) ASSERT_GT(test::to_camera(c, glm::dvec3(p)).z, 0.0) << c.image_name;
  const auto points = read_colmap_points3D(test::fern_dir() / "sparse" / "0");
  std::size_t total = 0, inside = 0;
  for (const auto& p : points)
    for (const auto& t : p.track) {
      ASSERT_GE(t.image_id, 1u);
      ASSERT_LE(t.image_id, 20u);
      ++total;
      if (test::inside(s.cameras[t.image_id - 1], test::project(s.cameras[t.image_id - 1], {p.xyz[0], p.xyz[1], p.xyz[2]})))
        ++inside;
    }
  EXPECT_GT(total, 10091u * 2);
  EXPECT_EQ(inside, total);
}

TEST(Llff, FernQuarterUsesImages4AndHalfIsAnError) {
  const Scene s4 = load_scene(test::fern_dir(), res(4));
  EXPECT_EQ(s4.images_folder, "images_4");
  EXPECT_EQ(s4.cameras[0].width, 1008);
  EXPECT_EQ(s4.cameras[0].height, 756);
  EXPECT_NEAR(s4.cameras[0].fx, 3260.526 / 4, 1e-3);
  EXPECT_EQ(s4.cameras[0].cx, 504.0);
  // No images_2/ and no images/: images_4 cannot be upsampled.
  expect_error([] { load_scene(test::fern_dir(), res(2)); }, {"fern", "-r 2", "images_2/", "images/", "images_4/"});
  expect_error([] { load_scene(test::fern_dir(), res(1)); }, {"fern", "-r 1", "images/"});
  expect_error([] { load_scene(test::fern_dir(), res(3)); }, {"1, 2, 4 or 8", "3"});
  expect_error([] { load_scene(test::fern_dir(), res(16)); }, {"16"});
}

// --image-source largest: fern's largest folder is images_4; -r 8 halves it with PIL's bicubic (the
// original loader's resize), with the same cameras as images_8.
TEST(Llff, LargestSourceResizesImages4WithPilBicubic) {
  SceneLoadOptions o = res(8);
  o.image_source = ImageSource::Largest;
  const Scene s = load_scene(test::fern_dir(), o);
  const Scene ref = load_scene(test::fern_dir(), res(8));
  EXPECT_EQ(s.images_folder, "images_4");
  EXPECT_EQ(s.image_source, ImageSource::Largest);
  ASSERT_EQ(s.cameras.size(), ref.cameras.size());
  for (std::size_t k = 0; k < s.cameras.size(); ++k) {
    EXPECT_EQ(s.cameras[k].width, 504);
    EXPECT_EQ(s.cameras[k].height, 378);
    EXPECT_EQ(s.cameras[k].resample_factor, 2);
    EXPECT_EQ(s.cameras[k].fx, ref.cameras[k].fx);
    EXPECT_EQ(s.cameras[k].cx, ref.cameras[k].cx);
  }
  const Image a = load_image(s, 3);
  const Image expect = resize_pil_bicubic(read_image(test::fern_dir() / "images_4" / "image003.png"), 504, 378);
  ASSERT_EQ(a.pixels.size(), expect.pixels.size());
  EXPECT_EQ(a.pixels, expect.pixels);
  // Not the prepared images_8 file, nor its area-resampled twin: another filter, the same picture.
  const Image prepared = load_image(ref, 3);
  double diff = 0.0;
  for (std::size_t i = 0; i < a.pixels.size(); ++i) diff += std::abs(a.pixels[i] - prepared.pixels[i]);
  diff /= static_cast<double>(a.pixels.size());
  EXPECT_GT(diff, 1e-4);
  EXPECT_LT(diff, 0.03);
}

TEST(Llff, EighthResampledFromImages4MatchesImages8) {
  // A fern copy without images_8: -r 8 must read images_4 and halve it by area averaging.
  const auto dir = test::scratch_dir();
  const auto root = test::make_fern_copy(dir, {"images_4"});
  const Scene s = load_scene(root, res(8));
  const Scene ref = load_scene(test::fern_dir(), res(8));
  EXPECT_EQ(s.images_folder, "images_4");
  ASSERT_EQ(s.cameras.size(), 20u);
  for (std::size_t k = 0; k < 20; ++k) {
    EXPECT_EQ(s.cameras[k].resample_factor, 2);
    EXPECT_EQ(s.cameras[k].width, 504);
    EXPECT_EQ(s.cameras[k].height, 378);
    EXPECT_EQ(s.cameras[k].fx, ref.cameras[k].fx);
    EXPECT_EQ(s.cameras[k].cx, ref.cameras[k].cx);
  }
  for (int k : {0, 13}) {
    const Image a = load_image(s, k);
    const Image b = load_image(ref, k);
    ASSERT_EQ(a.width, 504);
    ASSERT_EQ(a.height, 378);
    ASSERT_EQ(a.channels, 3);
    ASSERT_EQ(b.channels, 3);
    double diff = 0, mean_a = 0, mean_b = 0;
    for (std::size_t i = 0; i < a.pixels.size(); ++i) {
      diff += std::abs(a.pixels[i] - b.pixels[i]);
      mean_a += a.pixels[i];
      mean_b += b.pixels[i];
    }
    const double n = static_cast<double>(a.pixels.size());
    // The dataset's images_8 were made from the originals with another filter: close, not equal.
    EXPECT_LT(diff / n, 0.03) << k;
    EXPECT_NEAR(mean_a / n, mean_b / n, 0.01) << k;
  }
}

TEST(Llff, RoomPosesBoundsIsRejectedWithItsShape) {
  // room's poses_bounds.npy is a custom 41x14 array: as an LLFF scene (no sparse/0 model) it is an error.
  const auto dir = test::scratch_dir();
  const auto root = dir / "room_llff";
  fs::create_directories(root);
  fs::copy_file(test::room_dir() / "poses_bounds.npy", root / "poses_bounds.npy");
  fs::create_directory_symlink(test::room_dir() / "images", root / "images");
  expect_error([&] { load_scene(root); }, {(root / "poses_bounds.npy").string(), "41x14"});
}

void write_poses(const fs::path& path, std::vector<std::size_t> shape, std::vector<double> values) {
  std::vector<float> f(values.begin(), values.end());
  write_npy_f32(path, shape, f);
}

TEST(LlffBadInput, NanRowWrongShapeRowCountCorruptMagic) {
  const auto dir = test::scratch_dir();
  const auto root = test::make_fern_copy(dir);
  const auto npy = root / "poses_bounds.npy";
  const auto raw = read_npy(test::fern_dir() / "poses_bounds.npy");

  auto nan_row = raw.values;
  nan_row[7 * 17 + 3] = std::nan("");
  write_poses(npy, {20, 17}, nan_row);
  expect_error([&] { load_scene(root, res(8)); }, {npy.string(), "row 7", "non-finite"});
  auto inf_row = raw.values;
  inf_row[19 * 17 + 16] = INFINITY;
  write_poses(npy, {20, 17}, inf_row);
  expect_error([&] { load_scene(root, res(8)); }, {npy.string(), "row 19"});

  write_poses(npy, {19, 17}, std::vector<double>(raw.values.begin(), raw.values.begin() + 19 * 17));
  expect_error([&] { load_scene(root, res(8)); }, {npy.string(), "19 rows", "20 images"});

  write_poses(npy, {20, 15}, std::vector<double>(raw.values.begin(), raw.values.begin() + 20 * 15));
  expect_error([&] { load_scene(root, res(8)); }, {npy.string(), "20x15"});
  write_poses(npy, {340}, raw.values);
  expect_error([&] { load_scene(root, res(8)); }, {npy.string(), "340"});

  auto bad_rot = raw.values;
  bad_rot[3 * 17 + 0] += 0.5;
  write_poses(npy, {20, 17}, bad_rot);
  expect_error([&] { load_scene(root, res(8)); }, {npy.string(), "row 3", "orthonormal"});
  auto bad_hwf = raw.values;
  bad_hwf[2 * 17 + 14] = -1;
  write_poses(npy, {20, 17}, bad_hwf);
  expect_error([&] { load_scene(root, res(8)); }, {npy.string(), "row 2", "focal"});
  // Finite but impossible: a focal of 1e-300 pixels (the kNN of the random init met a non-finite point) or 1e-30, a
  // camera at 1e300 or 1e30 (its depth range became inf … inf).
  auto tiny_focal = raw.values;
  tiny_focal[4 * 17 + 14] = 1e-30;  // the file is float32
  write_poses(npy, {20, 17}, tiny_focal);
  expect_error([&] { load_scene(root, res(8)); }, {npy.string(), "row 4", "no pinhole camera's"});
  auto far_centre = raw.values;
  far_centre[5 * 17 + 8] = 1e30;
  write_poses(npy, {20, 17}, far_centre);
  expect_error([&] { load_scene(root, res(8)); }, {npy.string(), "row 5", "camera centre", "beyond"});
  auto mirrored = raw.values;  // the "down" column negated: orthonormal, determinant −1
  for (int r = 0; r < 3; ++r) mirrored[6 * 17 + r * 5 + 0] = -mirrored[6 * 17 + r * 5 + 0];
  write_poses(npy, {20, 17}, mirrored);
  expect_error([&] { load_scene(root, res(8)); }, {npy.string(), "row 6", "reflection"});

  std::string bytes = read_file(test::fern_dir() / "poses_bounds.npy");
  bytes[1] = 'X';
  test::write_bytes(npy, bytes);
  expect_error([&] { load_scene(root, res(8)); }, {npy.string(), "magic"});
  const std::string good = read_file(test::fern_dir() / "poses_bounds.npy");
  test::write_bytes(npy, good.substr(0, good.size() - 9));
  expect_error([&] { load_scene(root, res(8)); }, {npy.string(), "truncated"});
  // The header's shape says where the data ends: 16 more bytes are a damaged file, not ignored.
  test::write_bytes(npy, good + std::string(16, '\0'));
  expect_error([&] { load_scene(root, res(8)); },
               {npy.string(), "16 unexpected bytes after the .npy data", "340 values of 8 bytes"});
  test::write_bytes(npy, good);
  EXPECT_NO_THROW(load_scene(root, res(8)));
  // Hidden files (an interrupted atomic write, macOS metadata) are not images of the scene.
  test::write_bytes(root / "images_8" / ".image000.tmp123-0.png", "partial");
  test::write_bytes(root / "images_8" / "._image001.png", "metadata");
  EXPECT_EQ(load_scene(root, res(8)).cameras.size(), 20u);
}

TEST(LlffBadInput, MissingAndCorruptImages) {
  const auto dir = test::scratch_dir();
  const auto root = dir / "fern";
  fs::create_directories(root / "images_8");
  fs::copy_file(test::fern_dir() / "poses_bounds.npy", root / "poses_bounds.npy");
  for (int k = 0; k < 20; ++k) {
    const auto name = fmt::format("image{:03d}.png", k);
    fs::create_symlink(test::fern_dir() / "images_8" / name, root / "images_8" / name);
  }
  // No sparse/0 here: no points.
  EXPECT_EQ(load_scene(root, res(8)).sfm_points.size(), 0u);
  // A PNG whose header is intact but whose data is cut: loads (size from the header), fails to decode.
  const std::string png = read_file(test::fern_dir() / "images_8" / "image005.png");
  fs::remove(root / "images_8" / "image005.png");
  test::write_bytes(root / "images_8" / "image005.png", png.substr(0, 200));
  const Scene s = load_scene(root, res(8));
  EXPECT_EQ(s.cameras[5].width, 504);
  EXPECT_NO_THROW(load_image(s, 4));
  expect_error([&] { load_image(s, 5); }, {"image005.png"});
  expect_error([&] { load_image(s, 20); }, {"out of range"});
  expect_error([&] { load_image(s, -1); }, {"out of range"});
  // Garbage without any image header: an error at load, naming the file.
  test::write_bytes(root / "images_8" / "image005.png", "not an image at all");
  expect_error([&] { load_scene(root, res(8)); }, {"image005.png"});
  // A missing image: one image fewer than rows.
  fs::remove(root / "images_8" / "image005.png");
  expect_error([&] { load_scene(root, res(8)); }, {"poses_bounds.npy", "20 rows", "19 images"});
  // A training image of another size than its pose row: the focal length would not fit it. An error at
  // load (it was a warning, and the run trained with wrong intrinsics).
  fs::create_symlink(test::fern_dir() / "images_4" / "image005.png", root / "images_8" / "image005.png");
  expect_error([&] { load_scene(root, res(8)); },
               {"image005.png", "1008x756", "poses_bounds.npy row 5", "504x378 at 1/8"});
  const auto resized = resize_area(read_image(test::fern_dir() / "images_8" / "image005.png"), 500, 375);
  fs::remove(root / "images_8" / "image005.png");
  write_image(root / "images_8" / "image005.png", resized);
  expect_error([&] { load_scene(root, res(8)); }, {"image005.png", "500x375", "row 5"});
  // An image whose size changed after loading: load_image checks it.
  fs::remove(root / "images_8" / "image005.png");
  fs::create_symlink(test::fern_dir() / "images_8" / "image005.png", root / "images_8" / "image005.png");
  const Scene t = load_scene(root, res(8));
  fs::remove(root / "images_8" / "image005.png");
  fs::create_symlink(test::fern_dir() / "images_4" / "image005.png", root / "images_8" / "image005.png");
  expect_error([&] { load_image(t, 5); }, {"image005.png", "1008x756", "504x378"});
}

}  // namespace
}  // namespace d2gs
