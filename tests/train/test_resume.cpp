// Reliability of training runs, checkpoints and resume (issue 21): a resume refuses a checkpoint of
// another scene, resolution, split or configuration and an --iterations below it, without touching the
// run's outputs; one `d2gs train` per model folder; temporaries of killed writers are removed; a run
// interrupted before its first checkpoint can be started again; damaged and old checkpoints are refused.
// Short runs on fern (1/8 resolution, random initial points) keep these fast.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>
#include <functional>
#include <map>
#include <sstream>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/image.hpp"
#include "d2gs/train/trainer.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {
namespace fs = std::filesystem;

std::string fern() { return (test::shared_data() / "nerf_llff_data/fern").string(); }

TrainConfig small_run(const fs::path& out, int iterations) {
  TrainConfig c;
  c.source = fern();
  c.model_dir = out.string();
  c.resolution = 8;
  c.n_views = 3;
  c.method = "3dgs";
  c.iterations = iterations;
  c.quiet = true;
  c.seed = 1;
  c.init = "random";
  c.random_points = 500;
  return c;
}

// A finished 4-iteration run in `dir` with a checkpoint at iteration 2; returns the checkpoint.
fs::path finished_run_with_checkpoint(const fs::path& dir) {
  auto cfg = small_run(dir, 4);
  cfg.checkpoint_iterations = {2};
  Trainer(cfg).run();
  return dir / "chkpnt2.bin";
}

// The message of the d2gs::Error `make` throws ("" when it throws none).
template <typename F>
std::string error_of(F&& make) {
  try {
    make();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

// Every regular file under `dir` with its bytes.
std::map<std::string, std::string> snapshot(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) files[e.path().lexically_relative(dir).string()] = read_file(e.path());
  return files;
}

// The files added, removed or changed between two snapshots ("" when none).
std::string changes(const std::map<std::string, std::string>& before, const std::map<std::string, std::string>& after) {
  std::string out;
  for (const auto& [name, bytes] : before)
    if (!after.count(name) || after.at(name) != bytes) out += name + " ";
  for (const auto& [name, bytes] : after)
    if (!before.count(name)) out += name + " ";
  return out;
}

// A process id that no process has: a child that has exited and been reaped.
long dead_pid() {
  const pid_t pid = ::fork();
  if (pid == 0) ::_exit(0);
  int status = 0;
  ::waitpid(pid, &status, 0);
  return pid;
}

// Bad 1: resuming a 10-view checkpoint with 2 views read its camera queue out of bounds (exit 3,
// "internal: vector::_M_default_append", an invalid read in CpuRasterizer::forward).
TEST(Resume, RefusesACheckpointOfMoreTrainingViews) {
  const auto dir = test::scratch_dir();
  const std::string common = fmt::format("train -s '{}' -r 8 --init random --random-points 300 --quiet", fern());
  const auto first = test::run_cli(fmt::format("{} -m '{}' --n-views 10 --iterations 4 --checkpoint-iterations 3",
                                               common, (dir / "ten").string()));
  ASSERT_EQ(first.exit_code, 0) << first.output;
  const auto resumed = test::run_cli(fmt::format("{} -m '{}' --n-views 2 --iterations 8 --resume '{}'", common,
                                                 (dir / "two").string(), (dir / "ten/chkpnt3.bin").string()));
  EXPECT_EQ(resumed.exit_code, 1) << resumed.output;
  EXPECT_NE(resumed.output.find("d2gs: error: " + (dir / "ten/chkpnt3.bin").string() + ": cannot resume: it was "
                                "trained on views [1, 3, 5, 6, 9, 11, 13, 14, 17, 19], this run's training views are [1, 19]"),
            std::string::npos)
      << resumed.output;
  EXPECT_EQ(test::count_occurrences(resumed.output, "\n"), 1u) << "one line: " << resumed.output;
  EXPECT_FALSE(fs::exists(dir / "two/results.json"));
}

// Bad 2: a checkpoint continues only the run it was written by; nothing of the run's folder changes
// when it refuses.
TEST(Resume, RefusesAnotherSceneResolutionSplitOrConfigurationAndLeavesTheRunAlone) {
  const auto dir = test::scratch_dir();
  const auto ckpt = finished_run_with_checkpoint(dir / "run");
  const auto before = snapshot(dir / "run");
  ASSERT_TRUE(before.count("results.json"));

  struct Case {
    const char* what;
    std::function<void(TrainConfig&)> change;
    std::string expected;  // in the message, after "<checkpoint>: cannot resume: "
  };
  const std::vector<Case> cases = {
      {"another scene",
       [](TrainConfig& c) { c.source = (test::shared_data() / "llff_nex_reprocessed/room").string(); },
       "it was trained on scene " + fs::canonical(fern()).string() + ", this run reads " +
           fs::canonical(test::shared_data() / "llff_nex_reprocessed/room").string()},
      {"another resolution", [](TrainConfig& c) { c.resolution = 4; }, "it was trained at -r 8, this run uses -r 4"},
      {"another split", [](TrainConfig& c) { c.n_views = 5; },
       "it was trained on views [1, 10, 19], this run's training views are [1, 5, 10, 14, 19]"},
      {"other test views",
       [](TrainConfig& c) {
         c.train_views = {1, 10, 19};
         c.test_views = {0, 8};
       },
       "its test views were [0, 8, 16], this run's are [0, 8]"},
      {"another method", [](TrainConfig& c) { c.method = "d2gs"; },
       "it was trained with method = \"3dgs\", this run has \"d2gs\""},
      {"another seed", [](TrainConfig& c) { c.seed = 2; }, "it was trained with seed = 1, this run has 2"},
      {"another SH degree", [](TrainConfig& c) { c.sh_degree = 2; }, "it was trained with sh_degree = 3, this run has 2"},
      {"another loss weight", [](TrainConfig& c) { c.lambda_dssim = 0.5f; },
       "it was trained with lambda_dssim = 0.20000000298023224, this run has 0.5"},
      {"another initial cloud", [](TrainConfig& c) { c.random_points = 400; },
       "it was trained with random_points = 500, this run has 400"},
  };
  for (const auto& k : cases) {
    auto other = small_run(dir / "run", 4);
    k.change(other);
    const std::string message = error_of([&] { Trainer t(other, ckpt); });
    EXPECT_EQ(message.rfind(ckpt.string() + ": cannot resume: " + k.expected, 0), 0u) << k.what << ": " << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << k.what;
    EXPECT_EQ(changes(before, snapshot(dir / "run")), "") << k.what << ": the refused resume changed the run's folder";
  }

  // The same split given another way is the same run.
  auto same = small_run(dir / "same", 4);
  same.n_views = 0;
  same.train_views = {1, 10, 19};
  Trainer resumed(same, ckpt);
  EXPECT_EQ(resumed.iteration(), 2);

  // A folder that holds another run is not overwritten by a resume either.
  auto other_run = small_run(dir / "other", 2);
  other_run.seed = 2;
  Trainer(other_run).run();
  const auto other_before = snapshot(dir / "other");
  auto into_other = small_run(dir / "other", 4);
  const std::string message = error_of([&] { Trainer t(into_other, ckpt); });
  EXPECT_NE(message.find((dir / "other").string() + ": holds another run (scene \""), std::string::npos) << message;
  EXPECT_NE(message.find("method \"3dgs\", seed 2"), std::string::npos) << message;
  EXPECT_EQ(changes(other_before, snapshot(dir / "other")), "");

  // ... nor one of another scene with the same method, seed, resolution and split (the scene was not compared).
  auto room_run = small_run(dir / "room", 2);
  room_run.source = (test::shared_data() / "llff_nex_reprocessed/room").string();
  room_run.n_views = 0;
  room_run.train_views = {1, 10, 19};
  room_run.test_views = {0, 8, 16};
  Trainer(room_run).run();
  const auto room_before = snapshot(dir / "room");
  auto into_room = small_run(dir / "room", 4);
  const std::string room_message = error_of([&] { Trainer t(into_room, ckpt); });
  EXPECT_NE(room_message.find((dir / "room").string() + ": holds another run (scene \""), std::string::npos) << room_message;
  EXPECT_EQ(changes(room_before, snapshot(dir / "room")), "");

  // ... nor a folder of another program's files; a new folder holding only the copied checkpoint is fine.
  fs::create_directories(dir / "mine");
  write_file_atomic(dir / "mine/cameras.json", "[1, 2, 3]");
  const std::string mine_message = error_of([&] { Trainer t(small_run(dir / "mine", 4), ckpt); });
  EXPECT_NE(mine_message.find((dir / "mine").string() + ": is not empty and holds no d2gs run (cameras.json is there)"),
            std::string::npos)
      << mine_message;
  EXPECT_EQ(read_file(dir / "mine/cameras.json"), "[1, 2, 3]");
  fs::create_directories(dir / "copy");
  fs::copy_file(ckpt, dir / "copy/chkpnt2.bin");
  Trainer copied(small_run(dir / "copy", 4), dir / "copy/chkpnt2.bin");
  EXPECT_EQ(copied.iteration(), 2);
}

// A training image whose file changed under the same name and size (re-exported, edited) is not the image
// the checkpoint was trained on: resuming would silently continue on other pixels.
TEST(Resume, RefusesATrainingImageThatChangedUnderItsName) {
  const auto dir = test::scratch_dir();
  const fs::path scene = dir / "fern";
  fs::create_directories(scene);
  fs::create_symlink(fs::path(fern()) / "poses_bounds.npy", scene / "poses_bounds.npy");
  fs::create_directory_symlink(fs::path(fern()) / "sparse", scene / "sparse");
  for (const char* folder : {"images_4", "images_8"}) {
    fs::create_directories(scene / folder);
    for (const auto& e : fs::directory_iterator(fs::path(fern()) / folder))
      fs::create_symlink(e.path(), scene / folder / e.path().filename());
  }
  auto cfg = small_run(dir / "run", 4);
  cfg.source = scene.string();
  cfg.checkpoint_iterations = {2};
  Trainer(cfg).run();
  // Training view 10 (of 1, 10, 19), the file its image is decoded from: one pixel changed, same size.
  const fs::path file = scene / "images_4/image010.png";
  Image image = read_image(file);
  image.at(5, 5, 0) = 1.0f - image.at(5, 5, 0);
  fs::remove(file);
  write_image(file, image);
  const std::string message = error_of([&] { Trainer t(cfg, dir / "run/chkpnt2.bin"); });
  EXPECT_EQ(message.rfind((dir / "run/chkpnt2.bin").string() + ": cannot resume: training view 10 (image010.png) has "
                          "another image file than it was trained on (CRC-32 ", 0), 0u)
      << message;
}

// A camera whose pose changed in the scene's files (poses_bounds.npy re-exported with another pose for a
// training view) is not the camera the checkpoint was trained with, although every image is the same.
TEST(Resume, RefusesATrainingCameraThatMoved) {
  const auto dir = test::scratch_dir();
  const fs::path scene = dir / "fern";
  fs::create_directories(scene);
  fs::copy_file(fs::path(fern()) / "poses_bounds.npy", scene / "poses_bounds.npy");
  for (const char* folder : {"images_4", "images_8"}) {
    fs::create_directories(scene / folder);
    for (const auto& e : fs::directory_iterator(fs::path(fern()) / folder))
      fs::create_symlink(e.path(), scene / folder / e.path().filename());
  }
  auto cfg = small_run(dir / "run", 4);
  cfg.source = scene.string();
  cfg.checkpoint_iterations = {2};
  Trainer(cfg).run();
  // Row 10 of the N×17 array (training view 10 of 1, 10, 19): its x translation (column 3 of [R|t|hwf]) + 0.5.
  std::string bytes = read_file(scene / "poses_bounds.npy");
  const std::size_t header = 10 + (static_cast<unsigned char>(bytes[8]) | static_cast<unsigned char>(bytes[9]) << 8);
  const std::size_t at = header + 8 * (17 * 10 + 3);
  double x = 0;
  std::memcpy(&x, bytes.data() + at, 8);
  x += 0.5;
  std::memcpy(bytes.data() + at, &x, 8);
  fs::remove(scene / "poses_bounds.npy");
  write_file_atomic(scene / "poses_bounds.npy", bytes);
  const std::string message = error_of([&] { Trainer t(cfg, dir / "run/chkpnt2.bin"); });
  EXPECT_EQ(message, (dir / "run/chkpnt2.bin").string() + ": cannot resume: training view 10 (image010.png) has another "
                     "camera pose in the scene's files than it was trained with (centre moved or turned)")
      << message;
  // The same file restored: the run resumes.
  fs::remove(scene / "poses_bounds.npy");
  fs::copy_file(fs::path(fern()) / "poses_bounds.npy", scene / "poses_bounds.npy");
  Trainer resumed(cfg, dir / "run/chkpnt2.bin");
  EXPECT_EQ(resumed.iteration(), 2);
}

// Resuming at iteration t trains t+1... again: the log keeps its lines up to t, so that no iteration is logged
// twice (a run interrupted after its last checkpoint, or a finished run resumed from an earlier one).
TEST(Resume, TheLogIsCutBackToTheCheckpoint) {
  const auto dir = test::scratch_dir();
  auto cfg = small_run(dir / "run", 4);
  cfg.checkpoint_iterations = {2};
  cfg.log_every = 1;
  Trainer(cfg).run();
  const auto iterations = [&] {
    std::vector<int> its;
    std::istringstream in(read_file(dir / "run/train_log.jsonl"));
    for (std::string line; std::getline(in, line);) {
      const auto j = nlohmann::json::parse(line);
      if (!j.contains("event")) its.push_back(j["iteration"].get<int>());
    }
    return its;
  };
  ASSERT_EQ(iterations(), (std::vector<int>{1, 2, 3, 4}));
  {
    Trainer t(cfg, dir / "run/chkpnt2.bin");
    t.run();
  }
  EXPECT_EQ(iterations(), (std::vector<int>{1, 2, 3, 4}));
}

// The usual way to continue a run by hand: its own config.json, where "stereo" is recorded as the folder it
// resolved to.
TEST(Resume, FromTheRunsOwnConfigJson) {
  const auto dir = test::scratch_dir();
  const fs::path run = dir / "run";
  const auto first = test::run_cli(fmt::format("-q train -s '{}' -m '{}' -r 8 --n-views 3 --method d2gs --dafe-prior stereo "
                                               "--init-dense-method sgbm --init random --random-points 300 --iterations 4 --checkpoint-iterations 2 "
                                               "--quiet", fern(), run.string()));
  ASSERT_EQ(first.exit_code, 0) << first.output;
  const auto saved = nlohmann::json::parse(read_file(run / "config.json"));
  ASSERT_EQ(fs::path(saved["dafe_prior"].get<std::string>()), run / "init/depth");
  ASSERT_EQ(saved["dafe_prior_kind"], "depth");
  const std::string model = read_file(run / "point_cloud/iteration_4/point_cloud.ply");
  const auto again = test::run_cli(fmt::format("-q train --config '{}' --resume '{}'", (run / "config.json").string(),
                                               (run / "chkpnt2.bin").string()));
  ASSERT_EQ(again.exit_code, 0) << again.output;
  EXPECT_EQ(read_file(run / "point_cloud/iteration_4/point_cloud.ply"), model);
}

// Bad 3: --iterations below the checkpoint trained nothing, exited 0, and results.json named an
// iteration whose model did not exist.
TEST(Resume, RefusesIterationsBelowTheCheckpointAndFinishesFromTheLastOne) {
  const auto dir = test::scratch_dir();
  auto cfg = small_run(dir / "run", 6);
  cfg.checkpoint_iterations = {3, 6};
  Trainer(cfg).run();
  const auto before = snapshot(dir / "run");

  auto fewer = small_run(dir / "run", 4);
  std::string message = error_of([&] { Trainer t(fewer, dir / "run/chkpnt6.bin"); });
  EXPECT_EQ(message, (dir / "run/chkpnt6.bin").string() +
                         ": cannot resume: it is at iteration 6, beyond --iterations 4; resume with --iterations 6 or more");
  // Iteration 3 of a 6-iteration run took an optimiser step that the last iteration of a 3-iteration run does not.
  auto three = small_run(dir / "run", 3);
  message = error_of([&] { Trainer t(three, dir / "run/chkpnt3.bin"); });
  EXPECT_NE(message.find("cannot resume: it is iteration 3 of a 6-iteration run"), std::string::npos) << message;
  EXPECT_EQ(changes(before, snapshot(dir / "run")), "");

  // The checkpoint of the last iteration: nothing to train, the final model and results are those of the run.
  auto last = small_run(dir / "finish", 6);
  Trainer finish(last, dir / "run/chkpnt6.bin");
  finish.run();
  EXPECT_EQ(read_file(dir / "finish/point_cloud/iteration_6/point_cloud.ply"),
            read_file(dir / "run/point_cloud/iteration_6/point_cloud.ply"));
  const auto a = nlohmann::json::parse(read_file(dir / "run/results.json"));
  const auto b = nlohmann::json::parse(read_file(dir / "finish/results.json"));
  EXPECT_EQ(b["iteration"], 6);
  EXPECT_EQ(b["mean"], a["mean"]);
}

// Bad 6: two trainers on one model folder both ran (the "already holds a run" check was check-then-create,
// and a resume skipped it).
TEST(TrainLock, OneTrainerPerModelFolder) {
  const auto dir = test::scratch_dir();
  const auto ckpt = finished_run_with_checkpoint(dir / "run");
  const auto cfg = small_run(dir / "run", 4);
  {
    Trainer first(cfg, ckpt);
    const std::string message = error_of([&] { Trainer second(cfg, ckpt); });
    EXPECT_EQ(message, fmt::format("{}: another d2gs train (process {}) is running in this folder",
                                   (dir / "run").string(), ::getpid()));
    // The same from another process, and a fresh start in a folder being trained too.
    const auto cli = test::run_cli(fmt::format("train -s '{}' -m '{}' -r 8 --n-views 3 --iterations 4 --init random "
                                               "--random-points 500 --seed 1 --quiet --resume '{}'",
                                               fern(), (dir / "run").string(), ckpt.string()));
    EXPECT_EQ(cli.exit_code, 1) << cli.output;
    EXPECT_NE(cli.output.find("another d2gs train (process " + std::to_string(::getpid()) + ") is running"),
              std::string::npos)
        << cli.output;
    auto fresh = small_run(dir / "fresh", 4);
    Trainer started(fresh);
    EXPECT_NE(error_of([&] { Trainer again(fresh); }).find("another d2gs train"), std::string::npos);
  }
  // Released with the trainer.
  Trainer next(cfg, ckpt);
  EXPECT_EQ(next.iteration(), 2);
}

// Bad 7: a checkpoint write killed between open and rename left its temporary file for ever.
TEST(TrainLock, RemovesTemporariesOfKilledWritersOnTheNextStart) {
  const auto dir = test::scratch_dir();
  const auto ckpt = finished_run_with_checkpoint(dir / "run");
  const auto cfg = small_run(dir / "run", 4);
  const long dead = dead_pid();
  const long alive = ::getpid();  // this test: alive while the command runs
  const fs::path stale1 = dir / fmt::format("run/.chkpnt4.tmp{}-0.bin", dead);
  const fs::path stale2 = dir / fmt::format("run/point_cloud/iteration_4/.point_cloud.tmp{}-7.ply", dead);
  const std::vector<fs::path> kept = {dir / fmt::format("run/.chkpnt4.tmp{}-1.bin", alive),
                                      dir / "run/.chkpnt4.tmpx-1.bin", dir / "run/notes.tmp1-1.txt"};
  const std::string resume = fmt::format("train -s '{}' -m '{}' -r 8 --n-views 3 --iterations 4 --init random "
                                         "--random-points 500 --seed 1 --quiet --resume '{}'",
                                         fern(), (dir / "run").string(), ckpt.string());
  {
    // Only under the folder's lock: while another trainer holds it, nothing is removed.
    Trainer holder(cfg, ckpt);
    for (const auto& p : kept) write_file_atomic(p, "keep");
    write_file_atomic(stale1, "half a checkpoint");
    write_file_atomic(stale2, "half a model");
    const auto refused = test::run_cli(resume);
    EXPECT_EQ(refused.exit_code, 1) << refused.output;
    EXPECT_TRUE(fs::exists(stale1));
  }
  const auto r = test::run_cli(resume);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(fs::exists(stale1));
  EXPECT_FALSE(fs::exists(stale2));
  for (const auto& p : kept) EXPECT_TRUE(fs::exists(p)) << p;
  EXPECT_NE(r.output.find(fmt::format("{}: removed 2 temporary file(s) of writers that were killed: ",
                                      (dir / "run").string())),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find(stale1.filename().string()), std::string::npos) << r.output;
}

// Weak: a run stopped (SIGTERM, Ctrl-C) before its first checkpoint left a folder that refused a re-run.
TEST(Resume, RunInterruptedBeforeItsFirstCheckpointStartsAgain) {
  const auto dir = test::scratch_dir();
  const fs::path run = dir / "run";
  const std::string args = fmt::format("train -s '{}' -m '{}' -r 8 --n-views 3 --init random --random-points 500 --quiet",
                                       fern(), run.string());
  const int pid = test::start_in_background(fmt::format("'{}' {} --iterations 100000 --checkpoint-iterations 100000 >'{}' 2>&1",
                                                       test::cli_path().string(), args, (dir / "first.log").string()));
  ASSERT_GT(pid, 0);
  ASSERT_TRUE(test::wait_until([&] { return fs::exists(run / "train_log.jsonl") && fs::file_size(run / "train_log.jsonl") > 0; }))
      << read_file(dir / "first.log");
  ::kill(pid, SIGTERM);
  ASSERT_TRUE(test::wait_until([&] { return ::kill(pid, 0) != 0; }));
  ASSERT_FALSE(fs::exists(run / "results.json"));
  // It stopped at an iteration's end (core/interrupt.hpp), saying so, not where the signal found it.
  EXPECT_NE(read_file(dir / "first.log").find("d2gs: interrupted by SIGTERM at iteration "), std::string::npos)
      << read_file(dir / "first.log");
  const auto again = test::run_cli(args + " --iterations 3");
  ASSERT_EQ(again.exit_code, 0) << again.output;
  EXPECT_NE(again.output.find("starting the run again: the previous one was interrupted before it saved a model or a "
                              "checkpoint"),
            std::string::npos)
      << again.output;
  EXPECT_TRUE(fs::exists(run / "point_cloud/iteration_3/point_cloud.ply"));
  EXPECT_EQ(nlohmann::json::parse(read_file(run / "results.json"))["iteration"], 3);
  // The log is the new run's only.
  EXPECT_EQ(read_file(run / "train_log.jsonl").find("\"iteration\":10,"), std::string::npos);

  // A run that saved a model or a checkpoint is still never overwritten; the message says how to continue.
  auto cfg = small_run(dir / "ckpt", 4);
  cfg.checkpoint_iterations = {2};
  {
    Trainer t(cfg);
    for (int i = 0; i < 2; ++i) t.step();
    t.save_checkpoint(dir / "ckpt/chkpnt2.bin");
  }
  EXPECT_EQ(error_of([&] { Trainer t(cfg); }),
            fmt::format("{}: already holds an unfinished training run (continue it with --resume {}, or use a new folder)",
                        (dir / "ckpt").string(), (dir / "ckpt/chkpnt2.bin").string()));
  EXPECT_EQ(error_of([&] { Trainer t(small_run(run, 3)); }),
            run.string() + ": already holds a finished training run (use a new folder)");
  // A config.json of another program is no interrupted run: the folder is not written into.
  fs::create_directories(dir / "project");
  write_file_atomic(dir / "project/config.json", R"({"name": "my project", "version": 3})");
  write_file_atomic(dir / "project/notes.txt", "mine");
  EXPECT_EQ(error_of([&] { Trainer t(small_run(dir / "project", 3)); }),
            (dir / "project").string() + ": is not empty and holds no d2gs run; refusing to write into it");
  EXPECT_EQ(read_file(dir / "project/config.json"), R"({"name": "my project", "version": 3})");
}

// Weak: flipped bytes in a checkpoint were found only if a value went non-finite.
TEST(Resume, RefusesDamagedCheckpoints) {
  const auto dir = test::scratch_dir();
  const std::string bytes = read_file(finished_run_with_checkpoint(dir / "run"));
  auto resume = small_run(dir / "resumed", 4);

  std::string flipped = bytes;
  flipped[flipped.size() / 2] = static_cast<char>(flipped[flipped.size() / 2] ^ 0x01);  // a low mantissa bit of a value
  write_file_atomic(dir / "flipped.bin", flipped);
  std::string message = error_of([&] { Trainer t(resume, dir / "flipped.bin"); });
  EXPECT_EQ(message.rfind((dir / "flipped.bin").string() + ": damaged checkpoint: CRC-32 mismatch (stored ", 0), 0u)
      << message;

  write_file_atomic(dir / "truncated.bin", bytes.substr(0, bytes.size() - 1000));
  message = error_of([&] { Trainer t(resume, dir / "truncated.bin"); });
  EXPECT_EQ(message, fmt::format("{}: truncated checkpoint ({} bytes of {})", (dir / "truncated.bin").string(),
                                 bytes.size() - 1000, bytes.size()));
  EXPECT_FALSE(fs::exists(dir / "resumed/config.json")) << "nothing is written before the checkpoint is checked";
}

// Weak: checkpoints of format 1 (D2GSCKPT1) carry neither scene nor split, so they cannot be checked.
TEST(Resume, RefusesFormatOneCheckpointsSayingWhy) {
  const auto dir = test::scratch_dir();
  // Written by d2gs before format 2: fern -r 8, 3 views, 3dgs, seed 7, 40 random points, iteration 2 of 3.
  const fs::path old = test::source_dir() / "tests/train/fixtures/chkpnt2_format1_fern_r8_3views_3dgs.bin";
  ASSERT_EQ(read_file(old).substr(0, 10), "D2GSCKPT1\n");
  auto cfg = small_run(dir / "run", 3);
  cfg.seed = 7;
  cfg.random_points = 40;
  EXPECT_EQ(error_of([&] { Trainer t(cfg, old); }),
            old.string() + ": checkpoint format 1 (written by d2gs before 2026-11-25) records neither the scene nor the "
                           "split it was trained on, so a resume from it cannot be checked; train the run again");
}

}  // namespace
}  // namespace d2gs
