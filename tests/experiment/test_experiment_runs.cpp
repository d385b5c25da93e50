// `d2gs experiment` end to end on fern (1/8 resolution, 3 views, a few iterations): parallel runs, tables
// and reports, skipping finished runs, resuming an interrupted run from its checkpoint (bit-identically),
// passing over a damaged newest checkpoint, a killed experiment resuming, a failing run not stopping the
// others.
#include <csignal>
#include <chrono>
#include <thread>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/eval/sinkhorn.hpp"
#include "d2gs/experiment/runner.hpp"
#include "d2gs/train/checkpoint.hpp"
#include "report/chromium.hpp"
#include "test_paths.hpp"

namespace d2gs::experiment {
namespace {
namespace fs = std::filesystem;

using test::count_occurrences;

// A tiny experiment file: fern, 3 views, -r 8, `iterations` iterations.
fs::path write_config(const fs::path& dir, const nlohmann::json& methods, const std::vector<int>& seeds,
                      int iterations, int checkpoint_every, bool keep_checkpoints = false) {
  const nlohmann::json j = {
      {"name", "tiny"},
      {"data_root", test::shared_data().string()},
      {"scenes", {{{"name", "fern"}, {"source", "nerf_llff_data/fern"}, {"scene_preset", "llff/fern"}}}},
      {"views", {3}},
      {"seeds", seeds},
      // SGBM's initial points: seconds, where the default PatchMatch takes a minute (tests/geometry test it).
      {"train", {{"resolution", 8}, {"iterations", iterations}, {"log_every", 1}, {"init_dense_method", "sgbm"}}},
      {"methods", methods},
      {"checkpoint_every", checkpoint_every},
      {"keep_checkpoints", keep_checkpoints},
      {"imr", {{"samples", 200}}}};
  write_file_atomic(dir / "exp.json", j.dump(2));
  return dir / "exp.json";
}

std::string experiment(const fs::path& config, const fs::path& out, const std::string& extra, int* code) {
  const auto r = test::run_cli("experiment --config '" + config.string() + "' -o '" + out.string() + "' " + extra);
  *code = r.exit_code;
  return r.output;
}

double psnr_of(const fs::path& run) {
  return nlohmann::json::parse(read_file(run / "results.json"))["mean"]["PSNR"].get<double>();
}

// The folder's copy of the configuration (experiment.json, read back by --run-index and resumes, without
// a data root) names a relative initial cloud by its absolute path, at the train and at the method level.
TEST(ExperimentRuns, StoredStateKeepsRelativeInitCloudsUnderTheDataRoot) {
  const auto dir = test::scratch_dir();
  const fs::path cloud = fs::absolute(test::shared_data() / "published_init/fern/3_views_fused.ply").lexically_normal();
  for (const bool method_level : {false, true}) {
    nlohmann::json j = nlohmann::json::parse(read_file(write_config(
        dir, {{{"method", "dropgaussian"}, {"variant", "dense"}, {"options", {{"init", "dense"}}}},
              {{"method", "dropgaussian"}, {"variant", "cloud"}}},
        {0}, 6, 3)));
    if (method_level) j["methods"][1]["options"] = {{"init", "published_init/fern/3_views_fused.ply"}};
    else j["train"]["init"] = "published_init/fern/3_views_fused.ply";
    write_file_atomic(dir / "exp.json", j.dump(2));
    const ExperimentConfig config = load_experiment_config(dir / "exp.json", "");
    const fs::path out = dir / (method_level ? "method" : "train");
    write_experiment_state(out, config, expand_runs(config, out));
    const auto [stored, runs] = read_experiment_state(out);
    ASSERT_EQ(runs.size(), 2u);
    EXPECT_EQ(runs[0].train_config["init"], "dense") << method_level;
    EXPECT_EQ(runs[1].train_config["init"], cloud.string()) << method_level;
  }
}

// What a folder and its modes refuse before anything is written or trained (none of these trains).
TEST(ExperimentCli, ModesOtherExperimentsAndRunListsAreChecked) {
  const auto dir = test::scratch_dir();
  int code = 0;
  const auto config = write_config(dir, {{{"method", "3dgs"}}}, {0, 1}, 2, 1);
  const auto out = dir / "exp";
  // --list changes nothing, not even a new folder's state.
  experiment(config, out, "--list", &code);
  EXPECT_EQ(code, 0);
  EXPECT_FALSE(fs::exists(out / "experiment.json"));
  // One mode at a time, and options only where they apply.
  for (const char* extra : {"--list --collect", "--emit-slurm --run-index 1", "--collect --run-index 1",
                            "--list --jobs 2", "--list --slurm-cpus 3"}) {
    const std::string output = experiment(config, out, extra, &code);
    EXPECT_EQ(code, 1) << extra << "\n" << output;
    EXPECT_NE(output.find("d2gs: error: "), std::string::npos) << extra << "\n" << output;
  }
  EXPECT_FALSE(fs::exists(out));
  // An out-of-range --run-index writes nothing either.
  EXPECT_NE(experiment(config, out, "--run-index 7", &code).find("outside the experiment's 2 runs"), std::string::npos);
  EXPECT_FALSE(fs::exists(out / "experiment.json"));
  // The folder's state; another experiment's file is not given this folder.
  experiment(config, out, "--emit-slurm", &code);
  ASSERT_EQ(code, 0);
  const std::string state = read_file(out / "experiment.json");
  auto other = nlohmann::json::parse(read_file(config));
  other["name"] = "other";
  write_file_atomic(dir / "other.json", other.dump());
  const std::string repointed = experiment(dir / "other.json", out, "--emit-slurm", &code);
  EXPECT_EQ(code, 1) << repointed;
  EXPECT_NE(repointed.find(out.string() + ": holds experiment 'tiny'"), std::string::npos) << repointed;
  EXPECT_EQ(read_file(out / "experiment.json"), state);
  // A task of the array (--run-index) with an edited file whose run list differs from the folder's.
  auto more = nlohmann::json::parse(read_file(config));
  more["seeds"] = {5, 0, 1};
  write_file_atomic(dir / "more.json", more.dump());
  const std::string task = experiment(dir / "more.json", out, "--run-index 0", &code);
  EXPECT_EQ(code, 1) << task;
  EXPECT_NE(task.find("gives other runs than the experiment in"), std::string::npos) << task;
  EXPECT_FALSE(fs::exists(out / "runs/fern/3v/3dgs/seed5"));
  // Names that would give two runs one id, and a name with a line break (it reached the Slurm script).
  auto clash = nlohmann::json::parse(read_file(config));
  clash["scenes"][0]["name"] = "s__3v__3dgs";
  write_file_atomic(dir / "clash.json", clash.dump());
  EXPECT_NE(experiment(dir / "clash.json", dir / "clash", "--list", &code).find("(no '__')"), std::string::npos);
  EXPECT_EQ(code, 1);
  auto injected = nlohmann::json::parse(read_file(config));
  injected["name"] = "x\ntouch /tmp/INJECTED\n#";
  write_file_atomic(dir / "injected.json", injected.dump());
  EXPECT_NE(experiment(dir / "injected.json", dir / "inj", "--emit-slurm", &code).find("without control characters"),
            std::string::npos);
  EXPECT_EQ(code, 1);
  EXPECT_FALSE(fs::exists(dir / "inj/slurm"));
  EXPECT_NE(experiment(config, dir / "s2", "--emit-slurm --slurm-gpus -3", &code).find("--slurm-gpus must be ≥ 0"),
            std::string::npos);
  // A scene folder that is not there: one line before any run is started or any folder made.
  auto missing = nlohmann::json::parse(read_file(config));
  missing["scenes"][0]["source"] = "nerf_llff_data/no_such_scene";
  write_file_atomic(dir / "missing.json", missing.dump());
  const std::string absent = experiment(dir / "missing.json", dir / "absent", "", &code);
  EXPECT_EQ(code, 1) << absent;
  EXPECT_NE(absent.find("scene 'fern': its source " +
                        fs::absolute(test::shared_data() / "nerf_llff_data/no_such_scene").lexically_normal().string() +
                        " is not a folder here"),
            std::string::npos)
      << absent;
  EXPECT_FALSE(fs::exists(dir / "absent"));
  // More views than the scene has outside its test views (fern: 20 images, 17 of them not test views): one
  // line naming the experiment file and the run, before any folder is made; --list still lists the runs.
  auto many = nlohmann::json::parse(read_file(config));
  many["views"] = {3, 30};
  write_file_atomic(dir / "many.json", many.dump());
  const std::string too_many = experiment(dir / "many.json", dir / "many", "", &code);
  EXPECT_EQ(code, 1) << too_many;
  EXPECT_NE(too_many.find("many.json: run 2 (fern__30v__3dgs__seed0): --n-views 30: only 17 training views are available"),
            std::string::npos)
      << too_many;
  EXPECT_FALSE(fs::exists(dir / "many"));
  experiment(dir / "many.json", dir / "many", "--list", &code);
  EXPECT_EQ(code, 0);
}

TEST(ExperimentRuns, TwoMethodsTwoSeedsInParallelThenSkipped) {
  const auto dir = test::scratch_dir();
  const auto config = write_config(dir, {{{"method", "3dgs"}}, {{"method", "dropgaussian"}}}, {0, 1}, 6, 3);
  int code = -1;
  const std::string out = experiment(config, dir / "exp", "--jobs 2", &code);
  ASSERT_EQ(code, 0) << out;
  for (const char* m : {"3dgs", "dropgaussian"})
    for (const char* s : {"seed0", "seed1"}) {
      const fs::path run = dir / "exp/runs/fern/3v" / m / s;
      EXPECT_TRUE(fs::is_regular_file(run / "results.json")) << run;
      EXPECT_TRUE(fs::is_regular_file(run / "report.html")) << run;
      EXPECT_FALSE(fs::exists(run / "chkpnt3.bin")) << "checkpoints are removed once a run finished";
      EXPECT_FALSE(fs::exists(run / "chkpnt6.bin"));
    }
  EXPECT_NE(out.find("4 trained, 0 skipped, 0 failed"), std::string::npos) << out;
  // Seeds differ, and the same seed of another method too (the runs are really independent).
  EXPECT_NE(psnr_of(dir / "exp/runs/fern/3v/3dgs/seed0"), psnr_of(dir / "exp/runs/fern/3v/3dgs/seed1"));
  const std::string md = read_file(dir / "exp/tables/results.md");
  EXPECT_NE(md.find("### fern, 3 views"), std::string::npos) << md;
  EXPECT_NE(md.find("| 3dgs | "), std::string::npos) << md;
  EXPECT_NE(md.find("| dropgaussian | "), std::string::npos) << md;
  EXPECT_EQ(count_occurrences(md, " ± "), 1u + 2u * 4u) << md;  // the legend, then PSNR, SSIM, #G, time per row (no LPIPS/AVGE)
  EXPECT_EQ(count_occurrences(md, "| 2/2 |"), 2u) << md;
  const std::string csv = read_file(dir / "exp/tables/results.csv");
  EXPECT_EQ(count_occurrences(csv, "\n"), 3u) << csv;
  EXPECT_NE(csv.find("fern,3,dropgaussian,,dropgaussian,2,2,"), std::string::npos) << csv;
  // IMR per method over the two seeds.
  const auto imr = nlohmann::json::parse(read_file(dir / "exp/imr/fern__3v__3dgs.json"));
  EXPECT_TRUE(std::isfinite(imr["imr"].get<double>()));
  EXPECT_EQ(imr["models"].size(), 2u);
  EXPECT_TRUE(imr["solver"]["epsilon_scaling"].get<bool>());  // the cache is keyed by the solver settings too
  EXPECT_TRUE(imr["pairs"][0]["converged"].get<bool>());
  const std::string html = read_file(dir / "exp/report.html");
  EXPECT_EQ(count_occurrences(html, "<img src=\"data:image/jpeg;base64,"), 3u * 5u);  // 3 views × (GT + 2 renders + 2 errors)
  EXPECT_NE(html.find("<section id=\"imr\">"), std::string::npos);
  if (fs::exists(test::kChromium)) {  // the experiment report in a real browser: every image decodes, no errors
    const test::Loaded loaded = test::load(dir / "exp/report.html", dir / "profile");
    EXPECT_NE(loaded.dom.find("data-images-ok=\"15\""), std::string::npos) << loaded.dom.substr(0, 2000);
    EXPECT_EQ(loaded.dom.find("id=\"load-error\""), std::string::npos);
    EXPECT_EQ(test::page_errors(loaded.log), "");
  }

  // Again: everything is skipped, nothing retrained, the tables are rebuilt (IMR from its cache).
  const auto before = fs::last_write_time(dir / "exp/runs/fern/3v/3dgs/seed0/results.json");
  const std::string again = experiment(config, dir / "exp", "--jobs 2", &code);
  ASSERT_EQ(code, 0) << again;
  EXPECT_EQ(count_occurrences(again, "skipped, already finished"), 4u) << again;
  EXPECT_NE(again.find("0 trained, 4 skipped, 0 failed"), std::string::npos) << again;
  EXPECT_EQ(again.find("IMR of"), std::string::npos) << again;
  EXPECT_EQ(fs::last_write_time(dir / "exp/runs/fern/3v/3dgs/seed0/results.json"), before);
  // A cache written by another revision of the solver's iterations is recomputed.
  EXPECT_EQ(imr["solver"]["revision"].get<int>(), kSinkhornRevision);
  auto stale = imr;
  stale["solver"]["revision"] = kSinkhornRevision - 1;
  write_file_atomic(dir / "exp/imr/fern__3v__3dgs.json", stale.dump(2) + "\n");
  const std::string third = experiment(config, dir / "exp", "--jobs 2", &code);
  ASSERT_EQ(code, 0) << third;
  EXPECT_EQ(count_occurrences(third, "IMR of"), 1u) << third;  // that group only
  EXPECT_EQ(nlohmann::json::parse(read_file(dir / "exp/imr/fern__3v__3dgs.json"))["imr"], imr["imr"]);
  // collect alone, from the folder's experiment.json.
  const auto c = test::run_cli("experiment collect -o '" + (dir / "exp").string() + "' --no-imr");
  ASSERT_EQ(c.exit_code, 0) << c.output;
  EXPECT_NE(c.output.find("4 of 4 runs finished"), std::string::npos) << c.output;

  // An output-only change (how often the log is written) leaves the finished runs the experiment's.
  nlohmann::json edited = nlohmann::json::parse(read_file(config));
  edited["train"]["log_every"] = 2;
  write_file_atomic(config, edited.dump(2));
  const std::string fourth = experiment(config, dir / "exp", "--no-imr", &code);
  ASSERT_EQ(code, 0) << fourth;
  EXPECT_NE(fourth.find("0 trained, 4 skipped, 0 failed"), std::string::npos) << fourth;
  // A method's options changed under the same name: its finished runs are no longer what the experiment
  // configures, so they are refused, not counted as the new configuration's (and nothing is trained or
  // tabulated, the folder's state is left as it was).
  const std::string state = read_file(dir / "exp/experiment.json");
  const std::string table = read_file(dir / "exp/tables/results.md");
  edited["methods"][1]["options"] = {{"opacity_lr", 0.1}};
  write_file_atomic(config, edited.dump(2));
  for (const char* extra : {"--no-imr", "--collect --no-imr", "--emit-slurm"}) {
    const std::string changed = experiment(config, dir / "exp", extra, &code);
    EXPECT_EQ(code, 1) << extra << changed;
    EXPECT_NE(changed.find("dropgaussian/seed0: run "), std::string::npos) << extra << changed;
    EXPECT_NE(changed.find("finished with another configuration than the experiment now gives it (opacity_lr was "
                           "0.05, the experiment now gives 0.1)"),
              std::string::npos)
        << extra << changed;
    EXPECT_EQ(count_occurrences(changed, "\n"), 1u) << extra << changed;
  }
  EXPECT_EQ(read_file(dir / "exp/experiment.json"), state);
  EXPECT_EQ(read_file(dir / "exp/tables/results.md"), table);
  EXPECT_FALSE(fs::exists(dir / "exp/slurm"));
  const std::string listed = experiment(config, dir / "exp", "--list", &code);
  EXPECT_EQ(code, 0) << listed;
  EXPECT_EQ(count_occurrences(listed, "finished with another configuration: opacity_lr was 0.05"), 2u) << listed;
  EXPECT_EQ(count_occurrences(listed, "finished: PSNR"), 2u) << listed;  // 3dgs's runs are unchanged
}

TEST(ExperimentRuns, InterruptedRunResumesFromItsCheckpointBitIdentically) {
  const auto dir = test::scratch_dir();
  const auto config = write_config(dir, {{{"method", "d2gs"}, {"preset", "release"}}}, {3}, 6, 3, true);
  int code = -1;
  std::string out = experiment(config, dir / "exp", "--no-imr", &code);
  ASSERT_EQ(code, 0) << out;
  const fs::path run = dir / "exp/runs/fern/3v/d2gs/seed3";
  const double psnr = psnr_of(run);
  ASSERT_TRUE(fs::is_regular_file(run / "chkpnt3.bin"));
  // What a run killed between its checkpoint at 3 and the end leaves behind.
  for (const char* p : {"results.json", "report.html", "chkpnt6.bin"}) fs::remove(run / p);
  fs::remove_all(run / "test");
  fs::remove_all(run / "point_cloud");
  out = experiment(config, dir / "exp", "--no-imr", &code);
  ASSERT_EQ(code, 0) << out;
  EXPECT_NE(out.find("resuming from chkpnt3.bin"), std::string::npos) << out;
  EXPECT_EQ(psnr_of(run), psnr);  // the resumed run is the same run
  // The resumed run's log was cut back to the checkpoint's iteration: iteration 4, trained before the kill and
  // again after the resume, is logged once, and the curve has one record per iteration.
  const std::string log = read_file(run / "train_log.jsonl");
  EXPECT_EQ(count_occurrences(log, "\"iteration\":4,"), 1u) << log;
  const std::string html = read_file(run / "report.html");
  EXPECT_NE(html.find("<polyline"), std::string::npos);

  // A run folder left without any checkpoint starts again from scratch.
  for (const auto& e : fs::directory_iterator(run))
    if (e.path().extension() == ".bin" || e.path().filename() == "results.json") fs::remove(e.path());
  out = experiment(config, dir / "exp", "--no-imr", &code);
  ASSERT_EQ(code, 0) << out;
  EXPECT_NE(out.find("restarting (no checkpoint"), std::string::npos) << out;
  EXPECT_EQ(psnr_of(run), psnr);
}

TEST(ExperimentRuns, DamagedNewestCheckpointFallsBackToAnOlderOne) {
  const auto dir = test::scratch_dir();
  const auto config = write_config(dir, {{{"method", "3dgs"}}}, {0}, 6, 3, true);
  int code = -1;
  std::string out = experiment(config, dir / "exp", "--no-imr", &code);
  ASSERT_EQ(code, 0) << out;
  const fs::path run = dir / "exp/runs/fern/3v/3dgs/seed0";
  const double psnr = psnr_of(run);
  const std::string ckpt6 = read_file(run / "chkpnt6.bin");
  const auto interrupt = [&] {  // what a run killed after its last checkpoint leaves behind
    for (const char* p : {"results.json", "report.html"}) fs::remove(run / p);
    fs::remove_all(run / "test");
    fs::remove_all(run / "point_cloud");
  };
  // The newest checkpoint cut short (a full disk): the runner used to retry it, and fail, at every rerun.
  interrupt();
  write_file_atomic(run / "chkpnt6.bin", ckpt6.substr(0, ckpt6.size() / 2));
  out = experiment(config, dir / "exp", "--no-imr", &code);
  ASSERT_EQ(code, 0) << out;
  EXPECT_NE(out.find(fmt::format("resuming from chkpnt3.bin; passed over {}: truncated checkpoint ({} bytes of {})",
                                 (run / "chkpnt6.bin").string(), ckpt6.size() / 2, ckpt6.size())),
            std::string::npos)
      << out;
  EXPECT_EQ(psnr_of(run), psnr);  // the same run
  EXPECT_EQ(read_checkpoint(run / "chkpnt6.bin").state.iteration, 6);  // written again, whole

  // No checkpoint that reads back: start again, and say why.
  interrupt();
  for (const char* name : {"chkpnt3.bin", "chkpnt6.bin"}) {
    std::string bytes = read_file(run / name);
    bytes[bytes.size() / 2] = static_cast<char>(bytes[bytes.size() / 2] ^ 0x40);
    write_file_atomic(run / name, bytes);
  }
  out = experiment(config, dir / "exp", "--no-imr", &code);
  ASSERT_EQ(code, 0) << out;
  EXPECT_NE(out.find("restarting (no usable checkpoint; passed over " + (run / "chkpnt6.bin").string() +
                     ": damaged checkpoint: CRC-32 mismatch"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find((run / "chkpnt3.bin").string() + ": damaged checkpoint: CRC-32 mismatch"), std::string::npos) << out;
  EXPECT_EQ(psnr_of(run), psnr);
}

// `d2gs experiment --config CONFIG -o DIR/exp --no-imr` in the background, in a process group of its own
// (setsid), its output in DIR/first.log; returns its process id (0 if it did not start).
int start_experiment_in_its_own_group(const fs::path& config, const fs::path& dir) {
  return test::start_in_background("setsid '" + test::cli_path().string() + "' experiment --config '" + config.string() +
                                   "' -o '" + (dir / "exp").string() + "' --no-imr >'" + (dir / "first.log").string() +
                                   "' 2>&1");
}

TEST(ExperimentRuns, KilledExperimentResumes) {
  const auto dir = test::scratch_dir();
  const auto config = write_config(dir, {{{"method", "3dgs"}}}, {0}, 12, 2, true);
  const fs::path run = dir / "exp/runs/fern/3v/3dgs/seed0";
  // Kill the whole process group once the first checkpoint exists.
  const int pid = start_experiment_in_its_own_group(config, dir);
  ASSERT_GT(pid, 0);
  ASSERT_TRUE(test::wait_until([&] { return fs::exists(run / "chkpnt2.bin"); })) << read_file(dir / "first.log");
  ::kill(-pid, SIGKILL);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  ASSERT_FALSE(fs::exists(run / "results.json")) << "the run finished before it could be killed";
  int code = -1;
  const auto list = test::run_cli("experiment -o '" + (dir / "exp").string() + "' --list");
  EXPECT_EQ(list.exit_code, 0) << list.output;
  EXPECT_NE(list.output.find("runs/fern/3v/3dgs/seed0"), std::string::npos) << list.output;
  EXPECT_NE(list.output.find("interrupted at iteration "), std::string::npos) << list.output;
  EXPECT_NE(list.output.find("/12; resumes from chkpnt"), std::string::npos) << list.output;
  EXPECT_NE(list.output.find("1 runs: 0 finished, 0 running, 1 interrupted, 0 failed, 0 pending"), std::string::npos)
      << list.output;
  const std::string out = experiment(config, dir / "exp", "--no-imr", &code);
  ASSERT_EQ(code, 0) << out;
  EXPECT_NE(out.find("resuming from chkpnt"), std::string::npos) << out;
  EXPECT_TRUE(fs::is_regular_file(run / "results.json"));
  EXPECT_NE(out.find("1 trained"), std::string::npos) << out;
}

// SIGTERM (or Ctrl-C) to the runner: it starts no further run, asks the running one to stop (it stops at an
// iteration's end, keeping its checkpoints) and waits for it, then exits 130 saying so; the run is listed
// as interrupted, to resume.
TEST(ExperimentRuns, InterruptedExperimentStopsItsRunsAndSaysSo) {
  const auto dir = test::scratch_dir();
  const auto config = write_config(dir, {{{"method", "3dgs"}}}, {0, 1}, 100000, 2, true);
  const fs::path run = dir / "exp/runs/fern/3v/3dgs/seed0";
  const int pid = start_experiment_in_its_own_group(config, dir);
  ASSERT_GT(pid, 0);
  ASSERT_TRUE(test::wait_until([&] { return fs::exists(run / "chkpnt2.bin"); })) << read_file(dir / "first.log");
  ::kill(pid, SIGTERM);  // the runner only: it stops its child itself
  ASSERT_TRUE(test::wait_until([&] { return ::kill(pid, 0) != 0; }, std::chrono::seconds(60)));
  const std::string log = read_file(dir / "first.log");
  EXPECT_NE(log.find("interrupted: stopping the 1 running run(s)"), std::string::npos) << log;
  EXPECT_NE(log.find("d2gs: interrupted by SIGTERM (the unfinished runs resume from their checkpoints"), std::string::npos)
      << log;
  EXPECT_EQ(log.find("fern__3v__3dgs__seed1"), std::string::npos) << "a run was started after the signal:\n" << log;
  const std::string child_log = read_file(dir / "exp/logs/fern__3v__3dgs__seed0.log");
  EXPECT_NE(child_log.find("d2gs: interrupted by SIGTERM at iteration "), std::string::npos) << child_log;
  const auto list = test::run_cli("experiment -o '" + (dir / "exp").string() + "' --list");
  EXPECT_NE(list.output.find("2 runs: 0 finished, 0 running, 1 interrupted, 0 failed, 1 pending"), std::string::npos)
      << list.output;
}

TEST(ExperimentRuns, FailingRunIsReportedAndTheOthersFinish) {
  const auto dir = test::scratch_dir();
  const auto config = write_config(
      dir,
      {{{"method", "3dgs"}},
       {{"method", "d2gs"}, {"variant", "broken"}, {"options", {{"dafe_prior_dir", (dir / "no-priors").string()}}}}},
      {0}, 4, 2);
  int code = -1;
  const std::string out = experiment(config, dir / "exp", "--jobs 2 --no-imr", &code);
  EXPECT_EQ(code, 1) << out;
  EXPECT_NE(out.find("1 trained, 0 skipped, 1 failed"), std::string::npos) << out;
  EXPECT_NE(out.find("run 1 fern__3v__d2gs-broken__seed0: exit code 1: d2gs: error: "), std::string::npos) << out;
  EXPECT_NE(out.find((dir / "no-priors").string() + ": --dafe-prior: no such folder"), std::string::npos) << out;
  EXPECT_NE(out.find("d2gs: error: experiment tiny: 1 of 2 runs failed"), std::string::npos) << out;
  EXPECT_TRUE(fs::is_regular_file(dir / "exp/runs/fern/3v/3dgs/seed0/results.json"));
  const std::string md = read_file(dir / "exp/tables/results.md");
  EXPECT_NE(md.find("| d2gs-broken | — | — | — | — | — | — | — | 0/1 |"), std::string::npos) << md;
  // The report's run table says what --list says: the failed run with its error line.
  const std::string html = read_file(dir / "exp/report.html");
  EXPECT_NE(html.find("failed before its first logged iteration: d2gs: error: "), std::string::npos) << html;
  EXPECT_NE(html.find("(see logs/fern__3v__d2gs-broken__seed0.log)"), std::string::npos);
  EXPECT_NE(html.find("finished: PSNR "), std::string::npos);
  // --list: the finished run with its scores, the failed one with its error line.
  const auto list = test::run_cli("experiment -o '" + (dir / "exp").string() + "' --list");
  EXPECT_EQ(list.exit_code, 0) << list.output;
  const double psnr = psnr_of(dir / "exp/runs/fern/3v/3dgs/seed0");
  EXPECT_NE(list.output.find(fmt::format("runs/fern/3v/3dgs/seed0                          finished: PSNR {:.3f}", psnr)),
            std::string::npos)
      << list.output;
  EXPECT_NE(list.output.find("runs/fern/3v/d2gs-broken/seed0                   failed before its first logged "
                             "iteration: d2gs: error: "),
            std::string::npos)
      << list.output;
  EXPECT_NE(list.output.find("2 runs: 1 finished, 0 running, 0 interrupted, 1 failed, 0 pending"), std::string::npos)
      << list.output;
}

}  // namespace
}  // namespace d2gs::experiment
