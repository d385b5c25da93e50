// Experiment files: the shipped examples expand as documented; presets and overrides land in each run's
// configuration; bad files are one-line errors naming the file.
#include <gtest/gtest.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/experiment/experiment_config.hpp"
#include "test_paths.hpp"

namespace d2gs::experiment {
namespace {
namespace fs = std::filesystem;

// An experiment folder for expand_runs (which checks that it could be written) in this test's scratch
// folder, not a fixed /tmp path another program may hold as a file.
fs::path out_dir(const char* name) {
  static const fs::path base = test::scratch_dir();
  return base / name;
}

const RunSpec& find(const std::vector<RunSpec>& runs, const std::string& label, std::uint64_t seed) {
  for (const auto& r : runs)
    if (r.label == label && r.seed == seed) return r;
  throw std::runtime_error("no run " + label);
}

TEST(ExperimentConfig, FernExampleIsThreeMethodsTimesThreeSeeds) {
  const auto file = test::source_dir() / "configs/experiments/llff_fern_3views.json";
  const ExperimentConfig c = load_experiment_config(file, test::shared_data().string());
  const auto runs = expand_runs(c, out_dir("exp"));
  ASSERT_EQ(runs.size(), 9u);
  EXPECT_EQ(runs[0].dir, fs::path("runs/fern/3v/3dgs/seed0"));
  EXPECT_EQ(runs[4].dir, fs::path("runs/fern/3v/dropgaussian/seed1"));
  EXPECT_EQ(runs[8].dir, fs::path("runs/fern/3v/d2gs/seed2"));
  EXPECT_EQ(runs[8].id(), "fern__3v__d2gs__seed2");
  for (std::size_t k = 0; k < runs.size(); ++k) {
    const auto& t = runs[k].train_config;
    EXPECT_EQ(runs[k].index, static_cast<int>(k));
    EXPECT_EQ(t["resolution"], 8);
    EXPECT_EQ(t["iterations"], 10000);
    EXPECT_EQ(t["n_views"], 3);
    EXPECT_EQ(t["model_path"], (out_dir("exp") / runs[k].dir).string());
    EXPECT_EQ(t["source"], (test::shared_data() / "nerf_llff_data/fern").lexically_normal().string());
    EXPECT_EQ(t["checkpoint_iterations"].size(), 10u);  // every 1000, the last included
    EXPECT_EQ(t["checkpoint_iterations"].back(), 10000);
  }
  const auto& d2gs = find(runs, "d2gs", 1).train_config;
  EXPECT_EQ(d2gs["method"], "d2gs");
  EXPECT_EQ(d2gs["seed"], 1);
  EXPECT_EQ(d2gs["preset"], "release");
  EXPECT_EQ(d2gs["dd_depth_mode"], "release-dot");
  EXPECT_EQ(d2gs["scene_preset"], "llff/fern");
  EXPECT_DOUBLE_EQ(d2gs["dafe_tau"].get<double>(), 10.0);  // fern's far-mask percentage
  EXPECT_DOUBLE_EQ(d2gs["dd_weight_depth"].get<double>(), 0.7);
  EXPECT_EQ(find(runs, "3dgs", 0).train_config["preset"], "");
}

// A relative initial cloud is found under data_root, as the scene sources are; keywords stay keywords.
TEST(ExperimentConfig, RelativeInitCloudIsUnderTheDataRoot) {
  const auto file = test::source_dir() / "configs/experiments/llff_fern_fidelity.json";
  const ExperimentConfig c = load_experiment_config(file, test::shared_data().string());
  const auto runs = expand_runs(c, out_dir("fid"));
  ASSERT_EQ(runs.size(), 24u);
  const auto cloud = (test::shared_data() / "published_init/fern/3_views_fused.ply").lexically_normal();
  for (const auto& r : runs) EXPECT_EQ(r.train_config["init"], fs::absolute(cloud).string()) << r.id();
  const auto mvs = expand_runs(
      load_experiment_config(test::source_dir() / "configs/experiments/llff_fern_mvs.json", test::shared_data().string()),
      out_dir("mvs"));
  EXPECT_EQ(find(mvs, "dropgaussian-pm-init", 0).train_config["init"], "dense");
  EXPECT_EQ(find(mvs, "dropgaussian-pm-init", 0).train_config["init_dense_method"], "patchmatch");
  EXPECT_EQ(find(mvs, "d2gs-published-init", 2).train_config["init"], fs::absolute(cloud).string());
  // Under another data root the same file names a cloud that is not there: one line naming the file.
  try {
    (void)expand_runs(load_experiment_config(file, "/nonexistent-root"), out_dir("fid"));
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("llff_fern_fidelity.json"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("/nonexistent-root/published_init/fern/3_views_fused.ply"), std::string::npos)
        << e.what();
  }
}

TEST(ExperimentConfig, AblationExampleMirrorsThePaperTable) {
  const auto file = test::source_dir() / "configs/experiments/llff_fern_ablation.json";
  const ExperimentConfig c = load_experiment_config(file, test::shared_data().string());
  const auto runs = expand_runs(c, out_dir("abl"));
  ASSERT_EQ(runs.size(), 18u);
  const auto& no_depth = find(runs, "d2gs-density-layers", 0).train_config;
  EXPECT_EQ(no_depth["dd_use_depth_score"], false);
  EXPECT_EQ(no_depth["dd_use_density_score"], true);
  EXPECT_EQ(no_depth["dafe"], false);
  EXPECT_EQ(find(runs, "d2gs-depth-layers", 0).train_config["dd_use_density_score"], false);
  EXPECT_EQ(find(runs, "d2gs-density-depth", 0).train_config["dd_use_layers"], false);
  const auto& full = find(runs, "d2gs-full", 2).train_config;
  EXPECT_EQ(full["dafe"], true);
  EXPECT_EQ(full["dd_use_layers"], true);
  // The default D²GS settings: the release preset with fern's values.
  EXPECT_EQ(full["preset"], "release");
  EXPECT_EQ(full["scene_preset"], "llff/fern");
  EXPECT_DOUBLE_EQ(full["dd_weight_depth"].get<double>(), 0.7);
  EXPECT_DOUBLE_EQ(full["dafe_tau"].get<double>(), 10.0);
  EXPECT_EQ(full["dafe_loss_form"], "release");
  EXPECT_EQ(find(runs, "3dgs-baseline", 0).dir, fs::path("runs/fern/3v/3dgs-baseline/seed0"));
}

// A scene's own "train" keys (fern at -r 8, room and horns at -r 2 in one table): over the experiment's
// "train", under a method's "options".
TEST(ExperimentConfig, SceneTrainKeysApplyToThatScenesRunsOnly) {
  const auto file = test::source_dir() / "configs/experiments/llff_levers.json";
  const ExperimentConfig c = load_experiment_config(file, test::shared_data().string());
  const auto runs = expand_runs(c, out_dir("levers"));
  ASSERT_EQ(runs.size(), 3u * 9u * 3u);
  for (const auto& r : runs) {
    EXPECT_EQ(r.train_config["resolution"], r.scene == "fern" ? 8 : 2) << r.id();
    EXPECT_EQ(r.train_config["iterations"], 10000) << r.id();  // the experiment's "train"
    EXPECT_EQ(r.train_config["image_source"], "largest") << r.id();  // today's default
  }
  const auto dir = test::scratch_dir();
  write_file_atomic(dir / "scene_train.json", R"({"scenes": [
      {"name": "a", "source": "/data/a", "train": {"resolution": 2, "iterations": 50}},
      {"name": "b", "source": "/data/b"}],
    "views": [3], "train": {"iterations": 100},
    "methods": [{"method": "3dgs"}, {"method": "3dgs", "variant": "short", "options": {"iterations": 20}}]})");
  const auto mixed = expand_runs(load_experiment_config(dir / "scene_train.json"), out_dir("mixed"));
  ASSERT_EQ(mixed.size(), 4u);
  EXPECT_EQ(mixed[0].train_config["iterations"], 50);   // a: the scene's over the experiment's
  EXPECT_EQ(mixed[0].train_config["resolution"], 2);
  EXPECT_EQ(mixed[1].train_config["iterations"], 20);   // a, short: the method's over the scene's
  EXPECT_EQ(mixed[2].train_config["iterations"], 100);  // b: the experiment's
  EXPECT_EQ(mixed[2].train_config["resolution"], 1);
}

void expect_error(const std::string& text, const std::string& message) {
  const auto dir = test::scratch_dir();
  write_file_atomic(dir / "bad.json", text);
  try {
    load_experiment_config(dir / "bad.json");
    FAIL() << "expected an error for " << text;
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("bad.json: "), std::string::npos) << what;
    EXPECT_NE(what.find(message), std::string::npos) << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << what;
  }
}

TEST(ExperimentConfig, BadFilesAreOneLineErrorsNamingTheFile) {
  const std::string scenes = R"("scenes": [{"name": "fern", "source": "/data/fern"}], "views": [3])";
  expect_error("{", "invalid JSON");
  expect_error(R"({"views": [3], "methods": [{"method": "3dgs"}]})", "'scenes' must be a non-empty array");
  expect_error("{" + scenes + R"(, "methods": [{"method": "nerf"}]})", "unknown method 'nerf'");
  expect_error("{" + scenes + R"(, "methods": [{"method": "3dgs"}, {"method": "3dgs"}]})", "appears twice");
  expect_error("{" + scenes + R"(, "methods": [{"method": "d2gs", "preset": "best"}]})",
               "preset must be one of paper, release, plus (got 'best')");
  // A D²GS preset on another method would change (plus) or pretend to change (paper, release) it.
  expect_error("{" + scenes + R"(, "methods": [{"method": "dropgaussian", "preset": "plus"}]})",
               "preset 'plus' is a D2GS preset, but the method is dropgaussian");
  expect_error("{" + scenes + R"(, "methods": [{"method": "3dgs", "variant": "a/b"}]})", "variant name 'a/b'");
  expect_error("{" + scenes + R"(, "methods": [{"method": "3dgs"}], "train": {"seed": 3}})",
               "sets 'seed', which the experiment sets");
  expect_error("{" + scenes + R"(, "methods": [{"method": "3dgs"}], "train": {"iteratons": 3}})",
               "unknown key 'iteratons'");
  expect_error("{" + scenes + R"(, "methods": [{"method": "d2gs", "options": {"dafe": 1}}]})", "wrong type");
  expect_error("{" + scenes + R"(, "methods": [{"method": "3dgs"}], "colour": 1})", "unknown key 'colour'");
  expect_error(R"({"scenes": [{"name": "a b", "source": "x"}], "views": [3], "methods": [{"method": "3dgs"}]})",
               "scene name 'a b'");
  expect_error("{" + scenes + R"(, "seeds": [1, 1], "methods": [{"method": "3dgs"}]})", "'seeds' repeats");
  expect_error(R"({"scenes": [{"name": "a", "source": "x", "train": {"seed": 2}}], "views": [3],
                  "methods": [{"method": "3dgs"}]})",
               "scene a's 'train' sets 'seed', which the experiment sets");
  expect_error(R"({"scenes": [{"name": "a", "source": "x", "train": {"resolutoin": 2}}], "views": [3],
                  "methods": [{"method": "3dgs"}]})",
               "unknown key 'resolutoin'");
}

// Numbers used to go through get<int>(): "views": [4294967299] became 3 views, 5.7 became 5.
TEST(ExperimentConfig, NumbersAreTypeAndRangeChecked) {
  const std::string scenes = R"("scenes": [{"name": "fern", "source": "/data/fern"}])";
  const std::string methods = R"("methods": [{"method": "3dgs"}])";
  const auto with = [&](const std::string& more) { return "{" + scenes + ", " + methods + ", " + more + "}"; };
  expect_error(with(R"("views": [4294967299])"), "key 'views[0]': 4294967299 is out of range");
  expect_error(with(R"("views": [3.5])"), "key 'views[0]' must be an integer, got 3.5");
  expect_error(with(R"("views": [-1])"), "key 'views[0]': -1 is out of range");
  expect_error(with(R"("views": 3)"), "key 'views' must be a list");
  expect_error(with(R"("views": [3], "seeds": [0, -1])"), "key 'seeds[1]': -1 is out of range");
  expect_error(with(R"("views": [3], "seeds": [1.5])"), "key 'seeds[0]' must be an integer");
  expect_error(with(R"("views": [3], "checkpoint_every": 5.7)"), "key 'checkpoint_every' must be an integer");
  expect_error(with(R"("views": [3], "checkpoint_every": 4294967296)"), "key 'checkpoint_every': 4294967296 is out of range");
  expect_error(with(R"("views": [3], "checkpoint_every": 0)"), "key 'checkpoint_every': 0 is out of range");
  expect_error(with(R"("views": [3], "imr": {"samples": -1})"), "key 'samples': -1 is out of range");
  expect_error(with(R"("views": [3], "report": {"max_views": 2.5})"), "key 'max_views' must be an integer");
  expect_error(with(R"("views": [3], "train": {"iterations": 4294967301})"),
               "'train': key 'iterations': 4294967301 is out of range");
  expect_error(with(R"("views": [3], "train": {"iterations": 1e400})"), "invalid JSON");
  expect_error("{" + scenes + R"(, "views": [3], "methods": [{"method": "3dgs", "options": {"resolution": 4294967304}}]})",
               "method 3dgs options: key 'resolution': 4294967304 is out of range");
  // In range: taken as written.
  const auto dir = test::scratch_dir();
  write_file_atomic(dir / "ok.json", with(R"("views": [3, 9], "seeds": [18446744073709551615], "imr": {"samples": 0})"));
  const ExperimentConfig c = load_experiment_config(dir / "ok.json");
  EXPECT_EQ(c.views, (std::vector<int>{3, 9}));
  EXPECT_EQ(c.seeds, (std::vector<std::uint64_t>{UINT64_MAX}));
  EXPECT_EQ(c.imr_samples, 0u);
}

TEST(ExperimentConfig, InvalidRunConfigurationNamesTheRun) {
  const nlohmann::json j = {{"scenes", {{{"name", "fern"}, {"source", "/data/fern"}}}},
                            {"views", {3}},
                            {"methods", {{{"method", "d2gs"}, {"scene_preset", true}}}}};
  const ExperimentConfig c = parse_experiment_config(j, "exp.json");
  try {
    expand_runs(c, out_dir("x"));
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("exp.json: run 0 (fern__3v__d2gs__seed0): "), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("names none"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace d2gs::experiment

namespace d2gs::experiment {
namespace {

TEST(ExperimentConfig, EveryShippedConfigLoadsAndExpands) {
  std::size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(test::source_dir() / "configs/experiments")) {
    if (e.path().extension() != ".json") continue;
    ++files;
    const ExperimentConfig c = load_experiment_config(e.path(), test::shared_data().string());
    EXPECT_EQ(c.name, e.path().stem().string()) << e.path();
    const auto runs = expand_runs(c, out_dir("x"));
    EXPECT_EQ(runs.size(), c.scenes.size() * c.views.size() * c.methods.size() * c.seeds.size()) << e.path();
    for (const auto& r : runs) EXPECT_EQ(r.train_config["iterations"], 10000) << e.path();
  }
  EXPECT_GE(files, 4u);
}

// An experiment folder under a file: refused before anything runs, naming both paths.
TEST(ExperimentCli, OutputUnderAFileIsRefusedFirst) {
  const auto dir = test::scratch_dir();
  write_file_atomic(dir / "file", "x");
  const auto config = test::source_dir() / "configs/experiments/llff_fern_3views.json";
  const auto r = test::run_cli("experiment --config '" + config.string() + "' --data-root '" +
                               test::shared_data().string() + "' -o '" + (dir / "file/exp").string() + "'");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find((dir / "file").string() + " is a file, not a folder"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("internal"), std::string::npos) << r.output;
}

// `--config DIR/experiment.json -o DIR` used to replace the user's experiment file by the runner's state
// (silently), after which the same command failed on an "unknown key 'config'".
TEST(ExperimentCli, AnExperimentFileInsideItsOwnFolderIsNotOverwritten) {
  const auto dir = test::scratch_dir() / "inside";
  fs::create_directories(dir);
  const auto shipped = test::source_dir() / "configs/experiments/llff_fern_3views.json";
  const std::string text = read_file(shipped);
  write_file_atomic(dir / "experiment.json", text);
  const auto r = test::run_cli("experiment --config '" + (dir / "experiment.json").string() + "' --data-root '" +
                               test::shared_data().string() + "' -o '" + dir.string() + "' --list");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find((dir / "experiment.json").string() + ": is where the folder -o keeps the experiment's state"),
            std::string::npos)
      << r.output;
  EXPECT_EQ(read_file(dir / "experiment.json"), text);
}

// A folder that holds no experiment state but other files (a scene copy, a training run, a user's
// tables) is not written into: the runner's report.html, tables/ and logs/ would replace files of
// the same name without a word. An empty folder is fine.
TEST(ExperimentCli, AFolderOfOtherFilesIsNotWrittenInto) {
  const auto dir = test::scratch_dir();
  const auto shipped = test::source_dir() / "configs/experiments/llff_fern_3views.json";
  const auto command = [&](const fs::path& out) {
    return test::run_cli("experiment --config '" + shipped.string() + "' --data-root '" +
                         test::shared_data().string() + "' -o '" + out.string() + "' --emit-slurm");
  };
  fs::create_directories(dir / "mine" / "tables");
  write_file_atomic(dir / "mine" / "report.html", "mine");
  write_file_atomic(dir / "mine" / "tables" / "results.md", "my table");
  const auto r = command(dir / "mine");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find((dir / "mine").string() + ": is not empty and holds no d2gs experiment"), std::string::npos)
      << r.output;
  EXPECT_EQ(test::count_occurrences(r.output, "error"), 1u) << r.output;
  EXPECT_EQ(read_file(dir / "mine" / "report.html"), "mine");
  EXPECT_EQ(read_file(dir / "mine" / "tables" / "results.md"), "my table");
  EXPECT_FALSE(fs::exists(dir / "mine" / "experiment.json"));
  fs::create_directories(dir / "empty");
  const auto ok = command(dir / "empty");
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_TRUE(fs::exists(dir / "empty" / "experiment.json"));
  // Once it holds the state, the same command works on it again.
  const auto again = command(dir / "empty");
  EXPECT_EQ(again.exit_code, 0) << again.output;
}

TEST(ExperimentCli, AFoldersStateGivenAsTheExperimentFileSaysWhatItIs) {
  const auto dir = test::scratch_dir();
  const auto shipped = test::source_dir() / "configs/experiments/llff_fern_3views.json";
  const auto first = test::run_cli("experiment --config '" + shipped.string() + "' --data-root '" +
                                   test::shared_data().string() + "' -o '" + (dir / "a").string() + "' --emit-slurm");
  ASSERT_EQ(first.exit_code, 0) << first.output;
  const auto state = dir / "a" / "experiment.json";
  const auto r = test::run_cli("experiment --config '" + state.string() + "' -o '" + (dir / "b").string() + "' --list");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find(state.string() + ": is an experiment folder's state"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(fs::absolute(shipped).string()), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "b" / "experiment.json"));
  // The folder itself still runs from its state.
  const auto again = test::run_cli("experiment -o '" + (dir / "a").string() + "' --list");
  EXPECT_EQ(again.exit_code, 0) << again.output;
}

}  // namespace
}  // namespace d2gs::experiment
