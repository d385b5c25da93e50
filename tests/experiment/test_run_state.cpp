// Where a run stands, read from a hand-made experiment folder (experiment/run_state.hpp): each phase, the
// last complete line of train_log.jsonl, the checkpoint a resume would take, the error line of a failed
// run, and a results.json that cannot be read. The end-to-end `--list` of real runs (finished, failed,
// interrupted) is in test_experiment_runs.cpp.
#include <unistd.h>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/file_lock.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/experiment/run_state.hpp"
#include "d2gs/train/config.hpp"
#include "test_paths.hpp"

namespace d2gs::experiment {
namespace {
namespace fs = std::filesystem;

struct Folder {
  fs::path out = test::scratch_dir();
  RunSpec run;
  Folder() {
    run.scene = "fern";
    run.views = 3;
    run.label = "dropgaussian";
    run.method = "dropgaussian";
    run.seed = 1;
    run.dir = "runs/fern/3v/dropgaussian/seed1";
    run.train_config = {{"iterations", 10000}};
    fs::create_directories(out / "logs");
    fs::create_directories(out / run.dir);
  }
  fs::path log() const { return out / "logs" / (run.id() + ".log"); }
  fs::path lock() const { return out / "logs" / (run.id() + ".lock"); }
  fs::path dir() const { return out / run.dir; }
};

const std::string kTrainLog =
    "{\"elapsed_s\":10.0,\"gaussians\":100,\"iteration\":10,\"loss\":0.5}\n"
    "{\"event\":\"densify\",\"iteration\":20,\"cloned\":1}\n"
    "{\"elapsed_s\":40.0,\"gaussians\":120,\"iteration\":2500,\"loss\":0.1}\n"
    "{\"elapsed_s\":41.0,\"gaussians\":12";  // a line still being written

TEST(RunState, PendingWithoutALog) {
  const Folder f;
  const RunState s = inspect_run(f.out, f.run);
  EXPECT_EQ(s.phase, RunPhase::Pending);
  EXPECT_EQ(describe(s), "pending");
}

TEST(RunState, InterruptedRunNamesItsIterationAndCheckpoint) {
  const Folder f;
  write_file_atomic(f.log(), "[train dropgaussian] it 1000/10000\r[train dropgaussian] it 2000/10000\n");
  write_file_atomic(f.dir() / "train_log.jsonl", kTrainLog);
  RunState s = inspect_run(f.out, f.run);
  EXPECT_EQ(s.phase, RunPhase::Interrupted);
  EXPECT_EQ(describe(s), "interrupted at iteration 2500/10000; restarts from scratch (no checkpoint)");
  write_file_atomic(f.dir() / "chkpnt1000.bin", "x");
  write_file_atomic(f.dir() / "chkpnt2000.bin", "x");
  s = inspect_run(f.out, f.run);
  EXPECT_EQ(s.iteration, 2500);
  EXPECT_DOUBLE_EQ(s.elapsed_s, 40.0);
  EXPECT_EQ(s.checkpoint, 2000);
  EXPECT_EQ(describe(s), "interrupted at iteration 2500/10000; resumes from chkpnt2000.bin");
  // A lock file whose holder has ended is not a running run (the lock file stays after its holder).
  write_file_atomic(f.lock(), "999999999\n");
  EXPECT_EQ(inspect_run(f.out, f.run).phase, RunPhase::Interrupted);
  // Nor is one whose holder's id now belongs to another process (this one, started at another time).
  write_file_atomic(f.lock(), fmt::format("{} {}\n", ::getpid(), process_start_time(::getpid()) + 1));
  EXPECT_EQ(inspect_run(f.out, f.run).phase, RunPhase::Interrupted);
  // Nor one that a live runner released when the run ended (here: failed) while it went on with others.
  {
    const auto held = FileLock::try_acquire(f.lock());
    ASSERT_TRUE(held.has_value());
    EXPECT_EQ(inspect_run(f.out, f.run).phase, RunPhase::Running);
  }
  EXPECT_EQ(inspect_run(f.out, f.run).phase, RunPhase::Interrupted);
}

TEST(RunState, FailedRunGivesTheLogsErrorLine) {
  const Folder f;
  write_file_atomic(f.log(), "[I] mean reprojection error 0.25 px\n[train d2gs] it 10/10000\r"
                             "d2gs: error: /x/prior.npy: DAFE prior missing\n\n");
  const RunState s = inspect_run(f.out, f.run);
  EXPECT_EQ(s.phase, RunPhase::Failed);
  EXPECT_EQ(describe(s), "failed before its first logged iteration: d2gs: error: /x/prior.npy: DAFE prior missing");
  // The same log followed by a resumed attempt's progress is no longer a failure.
  write_file_atomic(f.log(), read_file(f.log()) + "[train d2gs] it 1000/10000");
  EXPECT_EQ(inspect_run(f.out, f.run).phase, RunPhase::Interrupted);
}

TEST(RunState, RunningWhileALiveProcessHoldsTheLock) {
  const Folder f;
  write_file_atomic(f.log(), "");
  write_file_atomic(f.dir() / "train_log.jsonl", kTrainLog);
  const auto held = FileLock::try_acquire(f.lock());
  ASSERT_TRUE(held.has_value());
  const RunState s = inspect_run(f.out, f.run);
  EXPECT_EQ(s.phase, RunPhase::Running);
  EXPECT_EQ(s.pid, static_cast<long>(::getpid()));
  // 2 500 iterations in 40 s: 7 500 more at that pace are 2 minutes.
  EXPECT_EQ(describe(s), "running (pid " + std::to_string(::getpid()) +
                             "): iteration 2500/10000 after 00:40, about 02:00 left at the mean pace so far");
  // A holder known to have ended its runs (a runner's report) is not running: the run was interrupted.
  EXPECT_EQ(inspect_run(f.out, f.run, static_cast<long>(::getpid())).phase, RunPhase::Interrupted);
}

TEST(RunState, FinishedRunGivesItsScoresOrWhyNot) {
  const Folder f;
  // The run's config.json as d2gs train writes it: every option.
  TrainConfig trained;
  update_from_json(trained, f.run.train_config);
  nlohmann::json recorded;
  to_json(recorded, trained);
  write_file_atomic(f.dir() / "config.json", recorded.dump());
  write_file_atomic(f.dir() / "results.json",
                    nlohmann::json{{"mean", {{"PSNR", 23.2071}, {"SSIM", 0.76237}, {"LPIPS", nullptr}}},
                                   {"gaussians", 69531},
                                   {"train_seconds", 2532.2}}
                        .dump());
  RunState s = inspect_run(f.out, f.run);
  EXPECT_EQ(s.phase, RunPhase::Finished);
  EXPECT_EQ(describe(s), "finished: PSNR 23.207, SSIM 0.7624, 69531 Gaussians, 2532 s");
  write_file_atomic(f.dir() / "results.json", "{\"mean\": {\"PSNR\": 23");
  s = inspect_run(f.out, f.run);
  EXPECT_EQ(s.phase, RunPhase::Finished);
  EXPECT_EQ(describe(s), "finished (results.json has no mean PSNR and SSIM)");
}

TEST(RunState, FinishedRunTrainedOtherwiseSaysHow) {
  const Folder f;
  write_file_atomic(f.dir() / "results.json",
                    nlohmann::json{{"mean", {{"PSNR", 23.2071}, {"SSIM", 0.76237}}}, {"gaussians", 1}}.dump());
  TrainConfig trained;
  update_from_json(trained, f.run.train_config);
  nlohmann::json recorded;
  to_json(recorded, trained);
  recorded["opacity_lr"] = 0.1;
  recorded["log_every"] = 1;  // output-only: not a difference
  write_file_atomic(f.dir() / "config.json", recorded.dump());
  EXPECT_EQ(describe(inspect_run(f.out, f.run)),
            "finished with another configuration: opacity_lr was 0.1, the experiment now gives 0.05");
  EXPECT_THROW(check_finished_runs_match(f.out, {f.run}), Error);
  recorded["opacity_lr"] = 0.05;
  write_file_atomic(f.dir() / "config.json", recorded.dump());
  EXPECT_EQ(describe(inspect_run(f.out, f.run)), "finished: PSNR 23.207, SSIM 0.7624, 1 Gaussians, 0 s");
  EXPECT_NO_THROW(check_finished_runs_match(f.out, {f.run}));
  // Scores of an earlier iteration (d2gs eval --iteration 7000 replaced the final ones) are no row of it.
  const std::string results = read_file(f.dir() / "results.json");
  auto earlier = nlohmann::json::parse(results);
  earlier["iteration"] = 7000;
  write_file_atomic(f.dir() / "results.json", earlier.dump());
  EXPECT_EQ(describe(inspect_run(f.out, f.run)).rfind("finished with another configuration: its results.json scores "
                                                      "iteration 7000, not the last of its 10000 (d2gs eval --iteration",
                                                      0),
            0u)
      << describe(inspect_run(f.out, f.run));
  EXPECT_THROW(check_finished_runs_match(f.out, {f.run}), Error);
  earlier["iteration"] = 10000;
  write_file_atomic(f.dir() / "results.json", earlier.dump());
  EXPECT_NO_THROW(check_finished_runs_match(f.out, {f.run}));
  write_file_atomic(f.dir() / "results.json", results);
  fs::remove(f.dir() / "config.json");  // a finished run that cannot be checked is not taken as matching
  EXPECT_NE(describe(inspect_run(f.out, f.run)).find("its config.json cannot be compared"), std::string::npos);
}

}  // namespace
}  // namespace d2gs::experiment
