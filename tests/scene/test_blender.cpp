// Blender scenes (lego): OpenGL->OpenCV conversion, focal from camera_angle_x, missing frames, alpha
// compositing, resolution and damaged JSON.
#include <gtest/gtest.h>

#include <cmath>

#include <nlohmann/json.hpp>

#include "d2gs/scene/blender.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/scene/split.hpp"
#include "scene_test_util.hpp"

namespace d2gs {
namespace {

namespace fs = std::filesystem;
using test::expect_error;

TEST(Blender, LegoLoadsTrainThenTestFrames) {
  const Scene s = load_scene(test::lego_dir());
  EXPECT_EQ(s.format, SceneFormat::Blender);
  ASSERT_EQ(s.cameras.size(), 125u);  // 100 train + the 25 test images present (every 8th)
  ASSERT_EQ(s.dataset_train.size(), 100u);
  ASSERT_EQ(s.dataset_test.size(), 25u);
  for (int i = 0; i < 100; ++i) {
    EXPECT_EQ(s.dataset_train[static_cast<std::size_t>(i)], i);
    EXPECT_EQ(s.cameras[static_cast<std::size_t>(i)].image_name, fmt::format("r_{}", i));
    EXPECT_EQ(s.cameras[static_cast<std::size_t>(i)].image_path, test::lego_dir() / "train" / fmt::format("r_{}.png", i));
  }
  for (int j = 0; j < 25; ++j) {
    const auto& c = s.cameras[static_cast<std::size_t>(100 + j)];
    EXPECT_EQ(s.dataset_test[static_cast<std::size_t>(j)], 100 + j);
    EXPECT_EQ(c.image_name, fmt::format("r_{}", 8 * j));
    EXPECT_EQ(c.image_path, test::lego_dir() / "test" / fmt::format("r_{}.png", 8 * j));
  }
  // One warning for the 175 test frames without an image.
  ASSERT_EQ(s.warnings.size(), 1u);
  EXPECT_NE(s.warnings[0].find("transforms_test.json"), std::string::npos);
  EXPECT_NE(s.warnings[0].find("175 of 200"), std::string::npos);
  EXPECT_TRUE(s.sfm_points.empty());

  const double angle = 0.6911112070083618;  // camera_angle_x of lego
  for (const Camera& c : s.cameras) {
    EXPECT_EQ(c.width, 800);
    EXPECT_EQ(c.height, 800);
    EXPECT_TRUE(c.has_alpha);
    EXPECT_NEAR(c.fx, 400.0 / std::tan(angle / 2), 1e-9);
    EXPECT_NEAR(c.fx, 1111.111, 1e-3);
    EXPECT_EQ(c.cx, 400.0);
    EXPECT_EQ(c.cy, 400.0);
    EXPECT_NEAR(c.fov_x(), angle, 1e-12);
  }
}

TEST(Blender, LegoCamerasLookAtTheObject) {
  // The lego cameras orbit the origin at radius ~4.03 and look at it: in OpenCV axes the origin is in
  // front of every camera and projects near the image centre. A wrong OpenGL->OpenCV conversion puts
  // it behind the camera.
  const Scene s = load_scene(test::lego_dir());
  for (const Camera& c : s.cameras) {
    const glm::dvec3 o = test::to_camera(c, glm::dvec3(0.0));
    EXPECT_GT(o.z, 3.5) << c.image_name;
    EXPECT_NEAR(glm::length(c.center_world()), 4.03, 0.05) << c.image_name;
    const glm::dvec2 uv = test::project(c, glm::dvec3(0.0));
    EXPECT_NEAR(uv.x, 400.0, 40.0) << c.image_name;
    EXPECT_NEAR(uv.y, 400.0, 40.0) << c.image_name;
    // Image "up" (-y) points to world +z (the turntable's up) for these upper-hemisphere views.
    const glm::dvec3 up_world = c.R_cam_to_world() * glm::dvec3(0, -1, 0);
    EXPECT_GT(up_world.z, 0.0) << c.image_name;
  }
  // Against the JSON: the centre is the last column of transform_matrix (to float32 precision: the
  // JSON rotations are orthonormal to ~1e-7 only, and the camera stores R and t = -R c).
  const auto j = nlohmann::json::parse(read_file(test::lego_dir() / "transforms_train.json"));
  const auto& m = j["frames"][26]["transform_matrix"];
  const auto centre = s.cameras[26].center_world();
  EXPECT_NEAR(centre.x, m[0][3].get<double>(), 1e-5);
  EXPECT_NEAR(centre.y, m[1][3].get<double>(), 1e-5);
  EXPECT_NEAR(centre.z, m[2][3].get<double>(), 1e-5);
  // Camera x axis = first column (unchanged), camera y = minus the second column.
  const auto c2w = s.cameras[26].R_cam_to_world();
  for (int r = 0; r < 3; ++r) {
    EXPECT_NEAR(c2w[0][r], m[r][0].get<double>(), 1e-9);
    EXPECT_NEAR(c2w[1][r], -m[r][1].get<double>(), 1e-9);
    EXPECT_NEAR(c2w[2][r], -m[r][2].get<double>(), 1e-9);
  }
}

TEST(Blender, DietNerfSplitOnLego) {
  SceneLoadOptions o;
  o.resolution = 2;
  o.background = glm::vec3(1.0f);
  const Scene s = load_scene(test::lego_dir(), o);
  SplitOptions so;
  so.n_views = 8;
  const Split split = make_split(s, so);
  EXPECT_EQ(split.train, (std::vector<int>{2, 16, 26, 55, 73, 75, 86, 93}));
  for (int i : split.train) EXPECT_EQ(s.cameras[static_cast<std::size_t>(i)].image_path.parent_path().filename(), "train");
  ASSERT_EQ(split.test.size(), 25u);
  EXPECT_EQ(split.test.front(), 100);
  EXPECT_EQ(split.test.back(), 124);
  EXPECT_EQ(s.cameras[0].width, 400);
  EXPECT_EQ(s.cameras[0].resample_factor, 2);
  EXPECT_NEAR(s.cameras[0].fx, 555.5555, 1e-3);
  // Other counts: evenly spaced over the 100 train frames.
  so.n_views = 3;
  EXPECT_EQ(make_split(s, so).train, (std::vector<int>{0, 50, 99}));
}

TEST(Blender, AlphaIsCompositedOnTheBackground) {
  SceneLoadOptions black, white;
  white.background = glm::vec3(1.0f);
  const Scene sb = load_scene(test::lego_dir(), black);
  const Scene sw = load_scene(test::lego_dir(), white);
  const Image raw = read_image(test::lego_dir() / "train" / "r_0.png");
  ASSERT_EQ(raw.channels, 4);
  const Image b = load_image(sb, 0), w = load_image(sw, 0);
  ASSERT_EQ(b.channels, 3);
  ASSERT_EQ(b.width, 800);
  std::size_t transparent = 0, opaque = 0;
  for (int y = 0; y < 800; y += 3)
    for (int x = 0; x < 800; x += 3) {
      const float a = raw.at(x, y, 3);
      transparent += a == 0.0f;
      opaque += a == 1.0f;
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(w.at(x, y, c) - b.at(x, y, c), 1.0f - a, 1e-6f);
        EXPECT_NEAR(b.at(x, y, c), raw.at(x, y, c) * a, 1e-6f);
      }
    }
  EXPECT_GT(transparent, 1000u);
  EXPECT_GT(opaque, 1000u);
  EXPECT_EQ(w.at(0, 0, 0), 1.0f);
  EXPECT_EQ(b.at(0, 0, 0), 0.0f);
  // At -r 8: 100x100, composited then area-averaged (the mean is preserved).
  SceneLoadOptions w8 = white;
  w8.resolution = 8;
  const Image small = load_image(load_scene(test::lego_dir(), w8), 0);
  ASSERT_EQ(small.width, 100);
  ASSERT_EQ(small.height, 100);
  double m_small = 0, m_full = 0;
  for (float v : small.pixels) m_small += v;
  for (float v : w.pixels) m_full += v;
  EXPECT_NEAR(m_small / static_cast<double>(small.pixels.size()), m_full / static_cast<double>(w.pixels.size()), 1e-4);
}

// A lego copy whose JSON files the test rewrites; the image folders are linked.
fs::path make_lego_copy(const fs::path& dir) {
  const auto root = dir / "lego";
  fs::create_directories(root);
  for (const char* f : {"transforms_train.json", "transforms_test.json"}) fs::copy_file(test::lego_dir() / f, root / f);
  for (const char* f : {"train", "test"}) fs::create_directory_symlink(test::lego_dir() / f, root / f);
  return root;
}

TEST(BlenderBadInput, DamagedJson) {
  const auto dir = test::scratch_dir();
  const auto root = make_lego_copy(dir);
  const auto path = root / "transforms_train.json";
  const auto good = nlohmann::json::parse(read_file(test::lego_dir() / "transforms_train.json"));

  test::write_bytes(path, read_file(test::lego_dir() / "transforms_train.json").substr(0, 5000));
  expect_error([&] { load_scene(root); }, {path.string(), "invalid JSON"});
  test::write_bytes(path, "{\"camera_angle_x\": NaN, \"frames\": []}\n\n");
  expect_error([&] { load_scene(root); }, {path.string(), "invalid JSON"});

  auto j = good;
  j.erase("camera_angle_x");
  test::write_bytes(path, j.dump());
  expect_error([&] { load_scene(root); }, {path.string(), "camera_angle_x"});
  j = good;
  j["frames"][7]["transform_matrix"][1][2] = "x";
  test::write_bytes(path, j.dump());
  expect_error([&] { load_scene(root); }, {path.string(), "frame 7", "./train/r_7", "not a number"});
  j = good;
  j["frames"][3]["transform_matrix"][0][0] = 5.0;
  test::write_bytes(path, j.dump());
  expect_error([&] { load_scene(root); }, {path.string(), "frame 3", "orthonormal"});
  j = good;
  j["frames"][4]["transform_matrix"][2] = nlohmann::json::array({1.0, 2.0});
  test::write_bytes(path, j.dump());
  expect_error([&] { load_scene(root); }, {path.string(), "frame 4", "row 2"});
  j = good;
  j["frames"][0].erase("file_path");
  test::write_bytes(path, j.dump());
  expect_error([&] { load_scene(root); }, {path.string(), "frame 0", "file_path"});
  // Finite but impossible: a mirrored frame (x negated: an orthonormal matrix of determinant −1), a field of
  // view so narrow that fx overflows, a camera at 1e300.
  j = good;
  for (int r = 0; r < 3; ++r) j["frames"][5]["transform_matrix"][r][0] = -j["frames"][5]["transform_matrix"][r][0].get<double>();
  test::write_bytes(path, j.dump());
  expect_error([&] { load_scene(root); }, {path.string(), "frame 5", "reflection"});
  j = good;
  j["camera_angle_x"] = 1e-300;
  test::write_bytes(path, j.dump());
  expect_error([&] { load_scene(root); }, {path.string(), "frame 0", "no pinhole camera's"});
  j = good;
  j["frames"][6]["transform_matrix"][1][3] = 1e300;
  test::write_bytes(path, j.dump());
  expect_error([&] { load_scene(root); }, {path.string(), "frame 6", "beyond 10⁹ units"});
  // The parser directly: a JSON document that is not an object.
  expect_error([] { parse_blender_transforms("[1, 2]", "t.json"); }, {"t.json", "object"});
}

// A transform_matrix must be a 4x4 rigid transform; a key given twice and an image named by two frames are
// errors naming the file and the frame (nlohmann keeps the last key; two frames of one image weigh it twice).
TEST(BlenderBadInput, MatrixRowsDuplicateKeysAndFrames) {
  const auto dir = test::scratch_dir();
  const auto root = make_lego_copy(dir);
  const auto path = root / "transforms_train.json";
  const auto good = nlohmann::json::parse(read_file(test::lego_dir() / "transforms_train.json"));

  auto j = good;
  j["frames"][9]["transform_matrix"].erase(3);
  test::write_bytes(path, j.dump());
  expect_error([&] { load_scene(root); }, {path.string(), "frame 9", "./train/r_9", "3 rows, expected 4"});
  j = good;
  j["frames"][9]["transform_matrix"][3] = nlohmann::json::array({1, 2, 3, 4});
  test::write_bytes(path, j.dump());
  expect_error([&] { load_scene(root); },
               {path.string(), "frame 9", "last row is [1, 2, 3, 4], expected [0, 0, 0, 1]"});
  j = good;
  j["frames"][9]["transform_matrix"].push_back(nlohmann::json::array({0, 0, 0, 1}));
  test::write_bytes(path, j.dump());
  expect_error([&] { load_scene(root); }, {path.string(), "frame 9", "5 rows"});
  j = good;
  j["frames"][9]["transform_matrix"][3] = nlohmann::json::array({0, 0, 1});
  test::write_bytes(path, j.dump());
  expect_error([&] { load_scene(root); }, {path.string(), "frame 9", "row 3 does not have 4 entries"});

  // A second camera_angle_x (text edit: the JSON library cannot write one).
  std::string text = good.dump();
  text.insert(text.size() - 1, R"(, "camera_angle_x": 0.2)");
  test::write_bytes(path, text);
  expect_error([&] { load_scene(root); }, {path.string(), "duplicate key 'camera_angle_x'"});
  text = good.dump();
  const auto frame4 = text.find(R"("file_path":"./train/r_4")");
  ASSERT_NE(frame4, std::string::npos);
  text.insert(frame4, R"("file_path":"./train/r_1",)");
  test::write_bytes(path, text);
  expect_error([&] { load_scene(root); }, {path.string(), "duplicate key 'file_path' in frames[4]"});

  // Two frames naming one image (also when spelt differently), and a test frame naming a train image.
  j = good;
  j["frames"][12]["file_path"] = "./train/r_3";
  test::write_bytes(path, j.dump());
  expect_error([&] { load_scene(root); },
               {path.string(), "frame 12 (./train/r_3) names the same image as frame 3 (./train/r_3)"});
  j["frames"][12]["file_path"] = "train/r_3.png";
  test::write_bytes(path, j.dump());
  expect_error([&] { load_scene(root); }, {path.string(), "frame 12 (train/r_3.png) names the same image as frame 3"});
  test::write_bytes(path, good.dump());
  auto t = nlohmann::json::parse(read_file(test::lego_dir() / "transforms_test.json"));
  t["frames"][0]["file_path"] = "./train/r_26";
  test::write_bytes(root / "transforms_test.json", t.dump());
  expect_error([&] { load_scene(root); },
               {"transforms_test.json", "frame 0 (./train/r_26) names the same image as transforms_train.json frame 26"});

  // The files as shipped still load.
  fs::copy_file(test::lego_dir() / "transforms_test.json", root / "transforms_test.json",
                fs::copy_options::overwrite_existing);
  const Scene s = load_scene(root);
  EXPECT_EQ(s.dataset_train.size(), 100u);
  EXPECT_EQ(s.dataset_test.size(), 25u);
}

// A train frame without its image would silently move the split (computed over the train frames): an
// error naming the frame. Test frames without an image are skipped with a warning, as lego ships only
// every 8th test image (../shared/data/SOURCES.md).
TEST(BlenderBadInput, MissingFramesAndFiles) {
  const auto dir = test::scratch_dir();
  const auto root = make_lego_copy(dir);
  auto j = nlohmann::json::parse(read_file(test::lego_dir() / "transforms_train.json"));
  j["frames"][10]["file_path"] = "./train/does_not_exist";
  test::write_bytes(root / "transforms_train.json", j.dump());
  expect_error([&] { load_scene(root); },
               {"transforms_train.json", "train frame 10", "./train/does_not_exist", "does_not_exist.png",
                "every train frame needs its image"});
  // The same frame missing from the test list: skipped, and said once.
  auto t = nlohmann::json::parse(read_file(test::lego_dir() / "transforms_test.json"));
  t["frames"][8]["file_path"] = "./test/does_not_exist";
  test::write_bytes(root / "transforms_test.json", t.dump());
  j = nlohmann::json::parse(read_file(test::lego_dir() / "transforms_train.json"));
  test::write_bytes(root / "transforms_train.json", j.dump());
  const Scene s = load_scene(root);
  EXPECT_EQ(s.dataset_train.size(), 100u);
  EXPECT_EQ(s.dataset_test.size(), 24u);  // 25 images present, one frame renamed away
  ASSERT_EQ(s.warnings.size(), 1u);
  EXPECT_NE(s.warnings[0].find("of 200 frames have no image file"), std::string::npos) << s.warnings[0];
  SplitOptions so;
  so.n_views = 8;
  EXPECT_EQ(make_split(s, so).train.size(), 8u);

  fs::remove(root / "transforms_test.json");
  const Scene no_test = load_scene(root);
  EXPECT_TRUE(no_test.dataset_test.empty());
  EXPECT_TRUE(make_split(no_test, {}).test.empty());

  j["frames"] = nlohmann::json::array();
  test::write_bytes(root / "transforms_train.json", j.dump());
  expect_error([&] { load_scene(root); }, {"transforms_train.json", "lists no train frame"});
}

}  // namespace
}  // namespace d2gs
