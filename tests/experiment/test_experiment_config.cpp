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

const RunSpec& find(const std::vector<RunSpec>& runs, const std::string& label, std::uint64_t seed) {
  for (const auto& r : runs)
    if (r.label == label && r.seed == seed) return r;
  throw std::runtime_error("no run " + label);
}

TEST(ExperimentConfig, FernExampleIsThreeMethodsTimesThreeSeeds) {
  const auto file = test::source_dir() / "configs/experiments/llff_fern_3views.json";
  const ExperimentConfig c = load_experiment_config(file, test::shared_data().string());
  const auto runs = expand_runs(c, "/tmp/exp");
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
    EXPECT_EQ(t["model_dir"], (fs::path("/tmp/exp") / runs[k].dir).string());
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

TEST(ExperimentConfig, AblationExampleMirrorsThePaperTable) {
  const auto file = test::source_dir() / "configs/experiments/llff_fern_ablation.json";
  const ExperimentConfig c = load_experiment_config(file, test::shared_data().string());
  const auto runs = expand_runs(c, "/tmp/abl");
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
}

TEST(ExperimentConfig, InvalidRunConfigurationNamesTheRun) {
  const nlohmann::json j = {{"scenes", {{{"name", "fern"}, {"source", "/data/fern"}}}},
                            {"views", {3}},
                            {"methods", {{{"method", "d2gs"}, {"scene_preset", true}}}}};
  const ExperimentConfig c = parse_experiment_config(j, "exp.json");
  try {
    expand_runs(c, "/tmp/x");
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
    const auto runs = expand_runs(c, "/tmp/x");
    EXPECT_EQ(runs.size(), c.scenes.size() * c.views.size() * c.methods.size() * c.seeds.size()) << e.path();
    for (const auto& r : runs) EXPECT_EQ(r.train_config["iterations"], 10000) << e.path();
  }
  EXPECT_GE(files, 4u);
}

}  // namespace
}  // namespace d2gs::experiment
