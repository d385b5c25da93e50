// Format detection, resolution handling (folder choice, resampling, intrinsics) and generic bad input.
#include <gtest/gtest.h>

#include <cmath>

#include <sys/stat.h>

#include "d2gs/scene/scene.hpp"
#include "scene_test_util.hpp"

namespace d2gs {
namespace {

namespace fs = std::filesystem;
using test::expect_error;

using test::res;

TEST(Scene, ResampledLengthRoundsHalfToEven) {
  // 3DGS: round(W / R) with Python's round (half to even).
  EXPECT_EQ(resampled_length(996, 2), 498);
  EXPECT_EQ(resampled_length(746, 4), 186);  // 186.5 -> 186
  EXPECT_EQ(resampled_length(996, 8), 124);  // 124.5 -> 124
  EXPECT_EQ(resampled_length(746, 8), 93);   // 93.25
  EXPECT_EQ(resampled_length(1010, 4), 252); // 252.5 -> 252
  EXPECT_EQ(resampled_length(1014, 4), 254); // 253.5 -> 254
  EXPECT_EQ(resampled_length(3, 8), 1);      // never 0
  EXPECT_EQ(resampled_length(777, 1), 777);
}

TEST(Scene, ChooseImageFolder) {
  const auto dir = test::scratch_dir();
  fs::create_directories(dir / "images_2");
  fs::create_directories(dir / "images_8");
  auto c = choose_image_folder(dir, 8);
  EXPECT_EQ(c.folder, "images_8");
  EXPECT_EQ(c.resample, 1);
  c = choose_image_folder(dir, 4);
  EXPECT_EQ(c.folder, "images_2");
  EXPECT_EQ(c.folder_factor, 2);
  EXPECT_EQ(c.resample, 2);
  expect_error([&] { choose_image_folder(dir, 1); }, {"images/", "images_2/, images_8/"});
  fs::create_directories(dir / "images");
  c = choose_image_folder(dir, 1);
  EXPECT_EQ(c.folder, "images");
  EXPECT_EQ(c.resample, 1);
  fs::remove(dir / "images_2");
  c = choose_image_folder(dir, 4);
  EXPECT_EQ(c.folder, "images");
  EXPECT_EQ(c.resample, 4);
  expect_error([&] { choose_image_folder(dir, 0); }, {"1, 2, 4 or 8"});
  // Largest: the smallest factor present that divides R (images/ first), never an upsampling.
  fs::create_directories(dir / "images_2");
  c = choose_image_folder(dir, 8, ImageSource::Largest);
  EXPECT_EQ(c.folder, "images");
  EXPECT_EQ(c.resample, 8);
  fs::remove(dir / "images");
  c = choose_image_folder(dir, 8, ImageSource::Largest);
  EXPECT_EQ(c.folder, "images_2");
  EXPECT_EQ(c.resample, 4);
  c = choose_image_folder(dir, 8, ImageSource::Folder);
  EXPECT_EQ(c.folder, "images_8");
  expect_error([&] { choose_image_folder(dir, 1, ImageSource::Largest); }, {"images/", "images_2/, images_8/"});
  EXPECT_EQ(image_source_from_string("largest"), ImageSource::Largest);
  EXPECT_STREQ(to_string(ImageSource::Folder), "folder");
  expect_error([] { image_source_from_string("pil"); }, {"'pil'", "folder, largest"});
  expect_error([&] { choose_image_folder(dir / "nothing", 2); }, {"nothing", "images_2/, images/"});
}

TEST(Scene, RoomResamplesFromFullResolution) {
  const Scene full = load_scene(test::room_dir());
  const Image full0 = load_image(full, 0);
  ASSERT_EQ(full0.width, 996);
  ASSERT_EQ(full0.height, 746);
  double full_mean = 0;
  for (float v : full0.pixels) full_mean += v;
  full_mean /= static_cast<double>(full0.pixels.size());

  struct Expect { int r, w, h; };
  for (const Expect e : {Expect{2, 498, 373}, Expect{4, 249, 186}, Expect{8, 124, 93}}) {
    SCOPED_TRACE(e.r);
    const Scene s = load_scene(test::room_dir(), res(e.r));
    EXPECT_EQ(s.images_folder, "images");
    EXPECT_EQ(s.resolution, e.r);
    const Camera& c = s.cameras[0];
    EXPECT_EQ(c.resample_factor, e.r);
    EXPECT_EQ(c.width, e.w);
    EXPECT_EQ(c.height, e.h);
    // Intrinsics follow the actual size, per axis.
    const double sx = e.w / 996.0, sy = e.h / 746.0;
    EXPECT_NEAR(c.fx, full.cameras[0].fx * sx, 1e-9);
    EXPECT_NEAR(c.fy, full.cameras[0].fy * sy, 1e-9);
    EXPECT_NEAR(c.cx, full.cameras[0].cx * sx, 1e-9);
    EXPECT_NEAR(c.cy, full.cameras[0].cy * sy, 1e-9);
    EXPECT_EQ(c.R_world_to_cam, full.cameras[0].R_world_to_cam);
    const Image im = load_image(s, 0);
    ASSERT_EQ(im.width, e.w);
    ASSERT_EQ(im.height, e.h);
    ASSERT_EQ(im.channels, 3);
    double mean = 0;
    for (float v : im.pixels) mean += v;
    mean /= static_cast<double>(im.pixels.size());
    EXPECT_NEAR(mean, full_mean, 0.01);  // area averaging keeps the mean (up to edge rounding)
    // A 2x2 block average of the full image near the centre matches the -r 2 pixel.
    if (e.r == 2) {
      for (int c3 = 0; c3 < 3; ++c3) {
        const float block = (full0.at(500, 300, c3) + full0.at(501, 300, c3) + full0.at(500, 301, c3) + full0.at(501, 301, c3)) / 4;
        EXPECT_NEAR(im.at(250, 150, c3), block, 1e-5f);
      }
    }
  }
}

TEST(Scene, RoomWithImagesNFolderUsesIt) {
  // A room copy with an images_4/ holding the -r 4 images, written by the test: used as is.
  const auto dir = test::scratch_dir();
  const auto root = test::make_room_copy(dir);
  const Scene s4 = load_scene(test::room_dir(), res(4));
  fs::create_directories(root / "images_4");
  for (std::size_t i = 0; i < s4.cameras.size(); ++i)
    write_image(root / "images_4" / s4.cameras[i].image_name, load_image(s4, static_cast<int>(i)));
  const Scene s = load_scene(root, res(4));
  EXPECT_EQ(s.images_folder, "images_4");
  EXPECT_EQ(s.cameras[7].resample_factor, 1);
  EXPECT_EQ(s.cameras[7].width, 249);
  EXPECT_EQ(s.cameras[7].fx, s4.cameras[7].fx);
  // -r 8 from images_4 by 2: 249/2 = 124.5 -> 124, 186/2 = 93.
  const Scene s8 = load_scene(root, res(8));
  EXPECT_EQ(s8.images_folder, "images_4");
  EXPECT_EQ(s8.cameras[0].resample_factor, 2);
  EXPECT_EQ(s8.cameras[0].width, 124);
  EXPECT_EQ(s8.cameras[0].height, 93);
  EXPECT_EQ(load_image(s8, 0).width, 124);
}

// A layout's marker that is there but no regular file, and a scene path that cannot be resolved: said
// so, not "unknown scene format" or "not found".
TEST(SceneBadInput, MarkerThatIsNoFileAndSymlinkLoop) {
  const auto dir = test::scratch_dir();
  const auto fifo = dir / "pipe_scene" / "poses_bounds.npy";
  fs::create_directories(fifo.parent_path());
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  expect_error([&] { load_scene(dir / "pipe_scene"); }, {fifo.string(), "is a named pipe, expected a file"});
  fs::create_directories(dir / "folder_scene" / "transforms_train.json");
  expect_error([&] { load_scene(dir / "folder_scene"); },
               {(dir / "folder_scene" / "transforms_train.json").string(), "is a folder, expected a file"});
  fs::create_directories(dir / "loop_marker" / "sparse" / "0");
  fs::create_symlink("images.bin", dir / "loop_marker" / "sparse" / "0" / "images.bin");
  expect_error([&] { load_scene(dir / "loop_marker"); },
               {(dir / "loop_marker" / "sparse" / "0" / "images.bin").string(), "cannot be read", "symbolic links"});
  // The scene folder itself: a loop of two links.
  fs::create_symlink(dir / "b", dir / "a");
  fs::create_symlink(dir / "a", dir / "b");
  expect_error([&] { load_scene(dir / "a"); }, {(dir / "a").string(), "cannot open the scene folder", "symbolic links"});
  // A dangling link is still "not found".
  fs::create_symlink(dir / "nowhere", dir / "dangling");
  expect_error([&] { load_scene(dir / "dangling"); }, {(dir / "dangling").string(), "scene folder not found"});
}

TEST(SceneBadInput, MissingFolderUnknownFormatBadOptions) {
  const auto dir = test::scratch_dir();
  expect_error([&] { load_scene(dir / "absent"); }, {(dir / "absent").string(), "not found"});
  // -s naming a file (e.g. the poses file instead of its folder): said so, not "not found".
  expect_error([&] { load_scene(test::fern_dir() / "poses_bounds.npy"); },
               {(test::fern_dir() / "poses_bounds.npy").string(), "is a file, not a scene folder"});
  fs::create_directories(dir / "empty" / "sparse" / "0");
  expect_error([&] { load_scene(dir / "empty"); },
               {"unknown scene format", "sparse/0/images.bin", "poses_bounds.npy", "transforms_train.json"});
  expect_error([&] { load_scene(test::room_dir(), res(3)); }, {"1, 2, 4 or 8", "3"});
  SceneLoadOptions o;
  o.background = glm::vec3(2.0f);
  expect_error([&] { load_scene(test::room_dir(), o); }, {"background"});
  // COLMAP model but no image folder at all.
  const auto root = dir / "model_only";
  fs::create_directories(root / "sparse");
  fs::create_directory_symlink(test::room_dir() / "sparse" / "0", root / "sparse" / "0");
  expect_error([&] { load_scene(root); }, {"model_only", "no image folder", "images/"});
}

}  // namespace
}  // namespace d2gs
