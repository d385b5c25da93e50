// Bad input to `d2gs train` and to the training configuration (issue 21): each fails early with one line
// that names the file or option and the problem, and nothing is written.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdint>
#include <functional>
#include <string>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/file_lock.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/model/ply.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/scene/split.hpp"
#include "d2gs/train/config.hpp"
#include "scene/scene_test_util.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {
namespace fs = std::filesystem;

std::string fern() { return (test::shared_data() / "nerf_llff_data/fern").string(); }

std::string config_error(const nlohmann::json& j) {
  TrainConfig c;
  try {
    update_from_json(c, j);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

// nlohmann's get<int>() wraps 4294967301 = 2^32 + 5 to 5 and truncates 5.7 to 5: the command line
// refuses both, and so must a JSON config.
TEST(TrainConfigJson, NumbersAreTypeAndRangeChecked) {
  TrainConfig c;
  EXPECT_THROW(update_from_json(c, nlohmann::json::parse(R"({"iterations": 4294967301})")), Error);
  EXPECT_EQ(c.iterations, TrainConfig{}.iterations) << "the wrapped value was taken";
  const std::string iterations = config_error(nlohmann::json::parse(R"({"iterations": 4294967301})"));
  EXPECT_NE(iterations.find("key 'iterations': 4294967301 is out of range"), std::string::npos) << iterations;
  EXPECT_NE(config_error(nlohmann::json::parse(R"({"resolution": 4294967304})")).find("key 'resolution'"),
            std::string::npos);
  EXPECT_NE(config_error(nlohmann::json::parse(R"({"iterations": 5.7})")).find("must be an integer, got 5.7"),
            std::string::npos);
  EXPECT_NE(config_error(nlohmann::json::parse(R"({"seed": -1})")).find("key 'seed': -1 is out of range"),
            std::string::npos);
  EXPECT_NE(config_error(nlohmann::json::parse(R"({"train_views": [1, 4294967299]})")).find("train_views[1]"),
            std::string::npos);
  EXPECT_NE(config_error(nlohmann::json::parse(R"({"position_lr": 1e39})")).find("key 'position_lr'"),
            std::string::npos);
  EXPECT_NE(config_error(nlohmann::json::parse(R"({"dafe": 1})")).find("wrong type"), std::string::npos);
  // In range: taken as written, including the largest seed.
  update_from_json(c, nlohmann::json::parse(
                          R"({"iterations": 2147483647, "seed": 18446744073709551615, "dafe_tau": 7, "resolution": 4})"));
  EXPECT_EQ(c.iterations, 2147483647);
  EXPECT_EQ(c.seed, UINT64_MAX);
  EXPECT_DOUBLE_EQ(c.dafe.tau, 7.0);
  EXPECT_EQ(c.resolution, 4);
}

TEST(TrainCli, ConfigFileNumbersAreCheckedAndTheFileNamed) {
  const auto dir = test::scratch_dir();
  const auto run = dir / "run";
  for (const auto& [text, expected] : std::vector<std::pair<std::string, std::string>>{
           {R"({"iterations": 4294967301})", "key 'iterations': 4294967301 is out of range"},
           {R"({"resolution": 4294967304})", "key 'resolution': 4294967304 is out of range"},
           {R"({"iterations": 5.7})", "key 'iterations' must be an integer, got 5.7"},
           {R"({"seed": -1})", "key 'seed': -1 is out of range"},
           {R"({"iterations": 1e400})", "invalid JSON"},  // nlohmann: out_of_range, not a parse_error
           {R"({"iteratons": 10})", "unknown key 'iteratons'"}}) {
    write_file_atomic(dir / "cfg.json", text);
    const auto r = test::run_cli(fmt::format("train --config '{}' -s '{}' -m '{}' -r 8 --n-views 3", (dir / "cfg.json").string(),
                                             fern(), run.string()));
    EXPECT_EQ(r.exit_code, 1) << text << "\n" << r.output;
    EXPECT_NE(r.output.find("d2gs: error: " + (dir / "cfg.json").string() + ": "), std::string::npos) << text << "\n" << r.output;
    EXPECT_NE(r.output.find(expected), std::string::npos) << text << "\n" << r.output;
    EXPECT_EQ(test::count_occurrences(r.output, "\n"), 1u) << r.output;
    EXPECT_FALSE(fs::exists(run)) << text;
  }
}

TEST(TrainCli, NegativeSeedIsRefusedNotWrapped) {
  const auto dir = test::scratch_dir();
  const auto r = test::run_cli(fmt::format("train -s '{}' -m '{}' --seed -1", (dir / "nowhere").string(), (dir / "run").string()));
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("--seed"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("scene folder not found"), std::string::npos) << "the seed was accepted:\n" << r.output;
  for (const std::string& args : {"init -s '" + (dir / "nowhere").string() + "'", std::string("demo")}) {
    const auto other = test::run_cli(fmt::format("{} -o '{}' --seed -1", args, (dir / "out").string()));
    EXPECT_NE(other.exit_code, 0) << args << "\n" << other.output;
    EXPECT_NE(other.output.find("--seed"), std::string::npos) << args << "\n" << other.output;
    EXPECT_FALSE(fs::exists(dir / "out")) << args;
  }
  // The largest seed is a seed: refused only for the missing scene.
  const auto big = test::run_cli(fmt::format("train -s '{}' -m '{}' --seed 18446744073709551615",
                                             (dir / "nowhere").string(), (dir / "run").string()));
  EXPECT_EQ(big.exit_code, 1) << big.output;
  EXPECT_NE(big.output.find("scene folder not found"), std::string::npos) << big.output;
  EXPECT_FALSE(fs::exists(dir / "run"));
}

TEST(TrainCli, UnknownInitListsTheChoices) {
  const auto dir = test::scratch_dir();
  const auto r = test::run_cli(fmt::format("train -s '{}' -m '{}' -r 8 --n-views 3 --init dence", fern(), (dir / "run").string()));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("--init 'dence' is not one of dense, sparse, random, sfm-all-views"), std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(dir / "run"));
}

TEST(TrainCli, ModelFolderUnderAFileFailsBeforeTraining) {
  const auto dir = test::scratch_dir();
  write_file_atomic(dir / "file", "x");
  const auto r = test::run_cli(fmt::format("train -s '{}' -m '{}' -r 8 --n-views 3 --init random --iterations 2",
                                           fern(), (dir / "file/run").string()));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_EQ(r.output.find("internal"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find((dir / "file/run").string()), std::string::npos) << r.output;
  EXPECT_NE(r.output.find((dir / "file").string() + " is a file, not a folder"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("random init"), std::string::npos) << "work was done first:\n" << r.output;
}

TEST(TrainCli, EmptyInitCloudIsNamed) {
  const auto dir = test::scratch_dir();
  write_point_cloud_ply(dir / "empty.ply", PointCloud{});
  const auto r = test::run_cli(fmt::format("-q train -s '{}' -m '{}' -r 8 --n-views 3 --init '{}' --iterations 2", fern(),
                                           (dir / "run").string(), (dir / "empty.ply").string()));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find((dir / "empty.ply").string() + ": the point cloud has no points"), std::string::npos)
      << r.output;
}

// room's images are JPEG photographs; a training view cut short used to be trained on (exit 0, only
// libjpeg's unnamed "Premature end of JPEG file" on stderr).
TEST(TrainCli, TruncatedTrainingJpegIsAnErrorNamingIt) {
  const auto dir = test::scratch_dir();
  const auto room = dir / "room";
  fs::create_directories(room / "sparse/0");
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"})
    fs::copy_file(test::room_dir() / "sparse/0" / f, room / "sparse/0" / f);
  fs::create_directories(room / "images");
  for (const auto& e : fs::directory_iterator(test::room_dir() / "images"))
    fs::create_symlink(e.path(), room / "images" / e.path().filename());
  SplitOptions so;
  so.n_views = 3;
  const Scene scene = load_scene(room, test::res(8));
  const int view = make_split(scene, so).train[1];
  const fs::path image = room / "images" / scene.cameras[static_cast<std::size_t>(view)].image_name;
  const std::string bytes = read_file(image);
  fs::remove(image);
  write_file_atomic(image, bytes.substr(0, bytes.size() * 2 / 3));
  const auto r = test::run_cli(fmt::format("-q train -s '{}' -m '{}' -r 8 --n-views 3 --init random --random-points 200 "
                                           "--iterations 1",
                                           room.string(), (dir / "run").string()));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("d2gs: error: " + image.string() + ": corrupt or truncated JPEG"), std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(dir / "run/point_cloud"));
  // The folder this failed run created is not left behind (it held only the lock file).
  EXPECT_FALSE(fs::exists(dir / "run"));
  // An existing empty folder stays, without the lock file, so a rerun is no "interrupted run".
  fs::create_directories(dir / "mine");
  const auto again = test::run_cli(fmt::format("-q train -s '{}' -m '{}' -r 8 --n-views 3 --init random --random-points "
                                               "200 --iterations 1", room.string(), (dir / "mine").string()));
  EXPECT_EQ(again.exit_code, 1) << again.output;
  EXPECT_TRUE(fs::is_directory(dir / "mine"));
  EXPECT_TRUE(fs::is_empty(dir / "mine"));
}

// config.json records the scene absolute; eval finds it from any working folder, resolves a relative
// recorded path against the run folder, and takes -s over the recorded one.
TEST(TrainCli, EvalFindsTheSceneFromAnotherWorkingFolder) {
  const auto dir = test::scratch_dir();
  fs::create_directories(dir / "work");
  fs::create_directory_symlink(fern(), dir / "work/fern");
  const fs::path before = fs::current_path();
  fs::current_path(dir / "work");
  const auto r = test::run_cli("-q train -s fern -m run -r 8 --n-views 3 --init random --random-points 300 --iterations 2");
  fs::current_path(before);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("[train "), std::string::npos) << "d2gs -q prints no progress line: " << r.output;
  const fs::path run = dir / "work/run";
  auto config = nlohmann::json::parse(read_file(run / "config.json"));
  EXPECT_EQ(config["source"], (dir / "work/fern").string());

  const double trained = nlohmann::json::parse(read_file(run / "results.json"))["train_seconds"].get<double>();
  fs::create_directories(dir / "elsewhere");
  fs::current_path(dir / "elsewhere");
  const auto e = test::run_cli(fmt::format("-q eval -m '{}' --json", run.string()));
  // The results of the same iteration keep the training time train recorded.
  EXPECT_EQ(nlohmann::json::parse(read_file(run / "results.json"))["train_seconds"].get<double>(), trained);
  // While a train (or another eval) holds the run folder, eval writes nothing into it.
  {
    const std::string results = read_file(run / "results.json");
    const auto held = FileLock::try_acquire(run / ".d2gs-train.lock");
    ASSERT_TRUE(held);
    const auto busy = test::run_cli(fmt::format("-q eval -m '{}'", run.string()));
    EXPECT_EQ(busy.exit_code, 1) << busy.output;
    EXPECT_NE(busy.output.find(run.string() + ": a d2gs train or eval (process " + std::to_string(::getpid()) +
                               ") is working in this folder"),
              std::string::npos)
        << busy.output;
    EXPECT_EQ(read_file(run / "results.json"), results);
  }
  // A path relative to the run folder (as a hand-written or moved config may hold).
  config["source"] = "../fern";
  write_file_atomic(run / "config.json", config.dump(2));
  const auto relative = test::run_cli(fmt::format("-q eval -m '{}' --json", run.string()));
  // A recorded scene that is gone: a clear error, and -s overrides it.
  config["source"] = "moved/away/fern";
  write_file_atomic(run / "config.json", config.dump(2));
  const auto gone = test::run_cli(fmt::format("-q eval -m '{}'", run.string()));
  const auto given = test::run_cli(fmt::format("-q eval -m '{}' -s '{}' --json", run.string(), fern()));
  fs::current_path(before);
  EXPECT_EQ(e.exit_code, 0) << e.output;
  EXPECT_EQ(relative.exit_code, 0) << relative.output;
  EXPECT_EQ(gone.exit_code, 1) << gone.output;
  EXPECT_NE(gone.output.find("moved/away/fern"), std::string::npos) << gone.output;
  EXPECT_NE(gone.output.find("give the scene with -s"), std::string::npos) << gone.output;
  EXPECT_EQ(given.exit_code, 0) << given.output;
  EXPECT_EQ(nlohmann::json::parse(read_file(run / "results.json"))["per_view"].size(), 3u);
}

// An evaluation that fails part-way (the last test view's image is truncated after its header) leaves the
// earlier test renders whole, byte for byte, with their results.json: the new images went to a sibling
// folder that only replaces them once every view is scored, and it is gone.
// eval replaces MODEL/test/ours_N whole; a file there that d2gs did not write is not removed with it.
TEST(TrainCli, EvalKeepsFilesItDidNotWriteInTheRenderFolder) {
  const auto dir = test::scratch_dir();
  const fs::path run = dir / "run";
  const auto t = test::run_cli(fmt::format("-q train -s '{}' -m '{}' -r 8 --n-views 3 --init random --random-points 300 "
                                           "--iterations 2", fern(), run.string()));
  ASSERT_EQ(t.exit_code, 0) << t.output;
  const fs::path ours = run / "test/ours_2";
  for (const fs::path& notes : {ours / "notes.txt", ours / "renders/notes.txt"}) {
    write_file_atomic(notes, "mine");
    const std::string results = read_file(run / "results.json");
    const auto e = test::run_cli(fmt::format("-q eval -m '{}'", run.string()));
    EXPECT_EQ(e.exit_code, 1) << e.output;
    EXPECT_NE(e.output.find("d2gs: error: " + ours.string() + ": holds " +
                            fs::relative(notes, ours).string() + ", which d2gs did not write there"),
              std::string::npos)
        << e.output;
    EXPECT_EQ(read_file(notes), "mine");
    EXPECT_EQ(read_file(run / "results.json"), results);
    fs::remove(notes);
  }
  fs::remove_all(ours);
  write_file_atomic(ours, "a file");
  const auto file = test::run_cli(fmt::format("-q eval -m '{}'", run.string()));
  EXPECT_EQ(file.exit_code, 1) << file.output;
  EXPECT_NE(file.output.find(ours.string() + ": exists and is not a folder of test renders"), std::string::npos)
      << file.output;
  EXPECT_EQ(read_file(ours), "a file");
  fs::remove(ours);
  const auto ok = test::run_cli(fmt::format("-q eval -m '{}'", run.string()));
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_TRUE(fs::is_regular_file(ours / "renders/image000.png"));
}

// eval reads the options back from the run's config.json: a value edited out of its range, or a file that is
// not a run's, is an error naming the file and the key (it used to be scored with whatever it held).
TEST(TrainCli, EvalRefusesAnEditedConfigJson) {
  const auto dir = test::scratch_dir();
  const fs::path run = dir / "run";
  const auto t = test::run_cli(fmt::format("-q train -s '{}' -m '{}' -r 8 --n-views 3 --init random --random-points 300 "
                                           "--iterations 2", fern(), run.string()));
  ASSERT_EQ(t.exit_code, 0) << t.output;
  const std::string original = read_file(run / "config.json");
  const auto edited = [&](const std::function<void(nlohmann::json&)>& edit, const std::string& expected) {
    nlohmann::json j = nlohmann::json::parse(original);
    edit(j);
    fs::remove(run / "config.json");
    write_file_atomic(run / "config.json", j.dump(2));
    const auto e = test::run_cli(fmt::format("-q eval -m '{}'", run.string()));
    EXPECT_EQ(e.exit_code, 1) << e.output;
    EXPECT_NE(e.output.find("d2gs: error: " + (run / "config.json").string() + ": " + expected), std::string::npos)
        << e.output;
    EXPECT_EQ(test::count_occurrences(e.output, "\n"), 1u) << e.output;
  };
  edited([](nlohmann::json& j) { j["n_views"] = -1; }, "key 'n_views' must be");
  edited([](nlohmann::json& j) { j["sh_degree"] = 9; }, "key 'sh_degree' must be");
  edited([](nlohmann::json& j) { j.erase("method"); }, "key 'method' is missing");
  edited([](nlohmann::json& j) { j["method"] = "4dgs"; }, "");
  fs::remove(run / "config.json");
  write_file_atomic(run / "config.json", original);
  const auto ok = test::run_cli(fmt::format("-q eval -m '{}'", run.string()));
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
}

// A test view that cannot be decoded is found before training, not after the model is saved (when the run
// would fail with a folder that neither resumes nor starts again).
TEST(TrainCli, ACorruptTestImageFailsBeforeTraining) {
  const auto dir = test::scratch_dir();
  const fs::path scene = dir / "fern";
  fs::create_directories(scene / "images_8");
  fs::copy_file(fern() + "/poses_bounds.npy", scene / "poses_bounds.npy");
  for (const auto& e : fs::directory_iterator(fs::path(fern()) / "images_8"))
    fs::create_symlink(e.path(), scene / "images_8" / e.path().filename());
  const std::string png = read_file(scene / "images_8/image008.png");  // test view 8 of 0, 8, 16
  fs::remove(scene / "images_8/image008.png");
  write_file_atomic(scene / "images_8/image008.png", png.substr(0, png.size() / 2));
  const auto r = test::run_cli(fmt::format("-q train -s '{}' -m '{}' -r 8 --n-views 3 --init random --random-points 300 "
                                           "--iterations 2", scene.string(), (dir / "run").string()));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find((scene / "images_8/image008.png").string() + ": corrupt or truncated PNG"), std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(dir / "run"));
}

TEST(TrainCli, EvalThatFailsPartWayLeavesTheEarlierRendersWhole) {
  const auto dir = test::scratch_dir();
  const fs::path scene = dir / "fern";
  fs::create_directories(scene / "images_8");
  fs::copy_file(fern() + "/poses_bounds.npy", scene / "poses_bounds.npy");
  for (const auto& e : fs::directory_iterator(fs::path(fern()) / "images_8"))
    fs::create_symlink(e.path(), scene / "images_8" / e.path().filename());
  const fs::path run = dir / "run";
  const auto t = test::run_cli(fmt::format("-q train -s '{}' -m '{}' -r 8 --n-views 3 --init random --random-points 300 "
                                           "--iterations 2", scene.string(), run.string()));
  ASSERT_EQ(t.exit_code, 0) << t.output;
  const fs::path renders = run / "test/ours_2/renders";
  // Marked, so that an evaluation writing view 0 again (the same model renders the same bytes) would show.
  write_file_atomic(renders / "image000.png", "the earlier evaluation's");
  std::vector<std::string> before;
  for (const char* name : {"image000.png", "image008.png", "image016.png"}) before.push_back(read_file(renders / name));
  const std::string results = read_file(run / "results.json");
  const std::string png = read_file(scene / "images_8/image016.png");
  fs::remove(scene / "images_8/image016.png");
  write_file_atomic(scene / "images_8/image016.png", png.substr(0, png.size() / 2));
  const auto e = test::run_cli(fmt::format("-q eval -m '{}'", run.string()));
  EXPECT_EQ(e.exit_code, 1) << e.output;
  EXPECT_NE(e.output.find((scene / "images_8/image016.png").string() + ": corrupt or truncated PNG"), std::string::npos)
      << e.output;
  int k = 0;
  for (const char* name : {"image000.png", "image008.png", "image016.png"})
    EXPECT_EQ(read_file(renders / name), before[static_cast<std::size_t>(k++)]) << name;
  EXPECT_EQ(read_file(run / "results.json"), results);
  EXPECT_FALSE(fs::exists(run / "test/ours_2.partial"));
}

}  // namespace
}  // namespace d2gs
