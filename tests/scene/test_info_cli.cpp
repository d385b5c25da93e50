// `d2gs info` end to end through the built program: JSON and table output, and bad input.
#include <gtest/gtest.h>

#include <sstream>

#include <nlohmann/json.hpp>

#include "scene_test_util.hpp"

namespace d2gs {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string q(const fs::path& p) { return "'" + p.string() + "'"; }

// Runs `d2gs -q info ARGS --json` (quiet: warnings go to the JSON only) and parses the output.
json info_json(const std::string& args) {
  const auto r = test::run_cli("-q info " + args + " --json");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  try {
    return json::parse(r.output);
  } catch (const json::exception& e) {
    ADD_FAILURE() << "output is not JSON: " << e.what() << "\n" << r.output;
    return {};
  }
}

std::vector<int> ints(const json& j) { return j.get<std::vector<int>>(); }

TEST(InfoCli, FernAcceptance) {
  const auto j = info_json("-s " + q(test::fern_dir()) + " -r 8 --n-views 3 --image-source folder");
  EXPECT_EQ(j["format"], "llff");
  EXPECT_EQ(j["root"], test::fern_dir().string());
  EXPECT_EQ(j["resolution"], 8);
  EXPECT_EQ(j["images_folder"], "images_8");
  // By default, what d2gs train reads: the largest folder (images_4/ here), resized to the same size.
  const auto d = info_json("-s " + q(test::fern_dir()) + " -r 8 --n-views 3");
  EXPECT_EQ(d["images_folder"], "images_4");
  EXPECT_EQ(d["cameras"][0]["width"], 504);
  ASSERT_EQ(j["cameras"].size(), 20u);
  for (std::size_t i = 0; i < 20; ++i) {
    const auto& c = j["cameras"][i];
    EXPECT_EQ(c["index"], i);
    EXPECT_EQ(c["name"], fmt::format("image{:03d}.png", i));
    EXPECT_EQ(c["width"], 504);
    EXPECT_EQ(c["height"], 378);
    EXPECT_NEAR(c["fx"].get<double>(), 407.57, 0.01);
    EXPECT_NEAR(c["fy"].get<double>(), 407.57, 0.01);
    EXPECT_EQ(c["cx"], 252.0);
    EXPECT_EQ(c["cy"], 189.0);
    ASSERT_EQ(c["R_world_to_cam"].size(), 3u);
    ASSERT_EQ(c["R_world_to_cam"][0].size(), 3u);
    ASSERT_EQ(c["t_world_to_cam"].size(), 3u);
    // centre = -R^T t, from the printed numbers.
    for (int a = 0; a < 3; ++a) {
      double centre = 0;
      for (int b = 0; b < 3; ++b) centre -= c["R_world_to_cam"][b][a].get<double>() * c["t_world_to_cam"][b].get<double>();
      EXPECT_NEAR(c["center"][a].get<double>(), centre, 1e-9);
    }
  }
  EXPECT_EQ(ints(j["train"]), (std::vector<int>{1, 10, 19}));
  EXPECT_EQ(ints(j["test"]), (std::vector<int>{0, 8, 16}));
  EXPECT_EQ(j["points"], 10091);
  EXPECT_TRUE(j["warnings"].empty());
}

TEST(InfoCli, RoomAndLego) {
  const auto room = info_json("-s " + q(test::room_dir()) + " -r 4");
  EXPECT_EQ(room["format"], "colmap");
  ASSERT_EQ(room["cameras"].size(), 41u);
  EXPECT_EQ(room["cameras"][0]["width"], 249);
  EXPECT_EQ(room["cameras"][0]["height"], 186);
  EXPECT_EQ(room["points"], 6111);
  EXPECT_EQ(ints(room["test"]), (std::vector<int>{0, 8, 16, 24, 32, 40}));
  EXPECT_EQ(room["train"].size(), 35u);

  const auto lego = info_json("-s " + q(test::lego_dir()) + " -r 2 --n-views 8 --white-background");
  EXPECT_EQ(lego["format"], "blender");
  ASSERT_EQ(lego["cameras"].size(), 125u);
  EXPECT_EQ(lego["cameras"][0]["width"], 400);
  EXPECT_EQ(lego["background"], json::array({1.0, 1.0, 1.0}));
  EXPECT_EQ(ints(lego["train"]), (std::vector<int>{2, 16, 26, 55, 73, 75, 86, 93}));
  EXPECT_EQ(lego["test"].size(), 25u);
  ASSERT_EQ(lego["warnings"].size(), 1u);
  EXPECT_NE(lego["warnings"][0].get<std::string>().find("transforms_test.json"), std::string::npos);
  EXPECT_EQ(lego["points"], 0);
}

TEST(InfoCli, ExplicitViewsAndTable) {
  const auto j = info_json("-s " + q(test::fern_dir()) + " -r 8 --train-views 2,5,11 --test-views 0,19");
  EXPECT_EQ(ints(j["train"]), (std::vector<int>{2, 5, 11}));
  EXPECT_EQ(ints(j["test"]), (std::vector<int>{0, 19}));
  const auto r = test::run_cli("info -s " + q(test::fern_dir()) + " -r 8 --n-views 3 --image-source folder");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("llff"), std::string::npos);
  EXPECT_NE(r.output.find("images_8"), std::string::npos);
  EXPECT_NE(r.output.find("1 10 19"), std::string::npos);
  EXPECT_NE(r.output.find("0 8 16"), std::string::npos);
  EXPECT_NE(r.output.find("image019.png"), std::string::npos);
  EXPECT_NE(r.output.find("504x378"), std::string::npos);
  EXPECT_NE(r.output.find("407.566"), std::string::npos);
  EXPECT_NE(r.output.find("10091"), std::string::npos);
}

// Bad input: exit 1 and a single line "d2gs: error: ..." that names the file.
void expect_cli_error(const std::string& args, std::initializer_list<std::string> fragments) {
  const auto r = test::run_cli(args);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  std::string out = r.output;
  ASSERT_FALSE(out.empty());
  if (out.back() == '\n') out.pop_back();
  EXPECT_EQ(out.find('\n'), std::string::npos) << "more than one line:\n" << r.output;
  EXPECT_EQ(out.rfind("d2gs: error: ", 0), 0u) << out;
  for (const auto& f : fragments) EXPECT_NE(out.find(f), std::string::npos) << "'" << f << "' not in: " << out;
}

TEST(InfoCli, BadInputExitsWithOneLine) {
  const auto dir = test::scratch_dir();
  expect_cli_error("info -s " + q(dir / "absent"), {(dir / "absent").string(), "not found"});
  expect_cli_error("info -s " + q(dir), {dir.string(), "unknown scene format"});
  expect_cli_error("info -s " + q(test::fern_dir()) + " -r 2", {"fern", "images_2/"});
  expect_cli_error("info -s " + q(test::fern_dir()) + " -r 3", {"1, 2, 4 or 8"});
  expect_cli_error("info -s " + q(test::fern_dir()) + " -r 8 --n-views 18", {"18"});
  expect_cli_error("info -s " + q(test::fern_dir()) + " -r 8 --train-views 1,8", {"also a test view"});
  expect_cli_error("info -s " + q(test::fern_dir()) + " -r 8 --train-views 1,99", {"99", "out of range"});
  // A truncated images.bin.
  const auto root = test::make_room_copy(dir);
  const auto images = root / "sparse" / "0" / "images.bin";
  test::write_bytes(images, read_file(images).substr(0, 1000));
  expect_cli_error("info -s " + q(root), {images.string(), "truncated"});
  // An unknown camera model.
  std::string cams = read_file(test::room_dir() / "sparse" / "0" / "cameras.bin");
  cams[12] = 42;
  test::write_bytes(root / "sparse" / "0" / "cameras.bin", cams);
  expect_cli_error("info -s " + q(root), {"cameras.bin", "unknown camera model id 42"});
  // -s without a folder is a usage error (CLI11), not a crash. (Without -s, info prints the backend:
  // tests/render/test_device_choice.cpp.)
  const auto r = test::run_cli("info -s");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_LT(r.exit_code, 128);
}

}  // namespace
}  // namespace d2gs
