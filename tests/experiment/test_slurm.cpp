// The Slurm job-array script: one task per run, each running `d2gs experiment --run-index` into the shared
// folder; the collect script; quoting; --emit-slurm runs nothing.
#include <gtest/gtest.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/experiment/slurm.hpp"
#include "test_paths.hpp"

namespace d2gs::experiment {
namespace {
namespace fs = std::filesystem;

ExperimentConfig nine_runs() {
  return load_experiment_config(test::source_dir() / "configs/experiments/llff_fern_3views.json",
                                test::shared_data().string());
}

TEST(Slurm, ArrayScriptHasOneTaskPerRunAndRunsThemByIndex) {
  SlurmOptions o;
  o.program = "/opt/d2gs/bin/d2gs";
  o.out_dir = "/shared/exp it's";
  o.partition = "gpu";
  o.time = "01:30:00";
  o.cpus = 16;
  o.gpus = 1;
  o.mem = "32G";
  o.max_parallel = 4;
  const std::string s = slurm_array_script(nine_runs(), 9, o);
  EXPECT_EQ(s.rfind("#!/bin/bash\n", 0), 0u);
  for (const char* line : {"#SBATCH --job-name=d2gs-llff_fern_3views\n", "#SBATCH --array=0-8%4\n",
                           "#SBATCH --partition=gpu\n", "#SBATCH --cpus-per-task=16\n", "#SBATCH --gres=gpu:1\n",
                           "#SBATCH --mem=32G\n", "#SBATCH --time=01:30:00\n",
                           "#SBATCH --output=/shared/exp it's/logs/slurm-%A_%a.out\n", "set -euo pipefail\n",
                           "D2GS='/opt/d2gs/bin/d2gs'\n", "OUT='/shared/exp it'\\''s'\n",
                           "exec \"$D2GS\" experiment -o \"$OUT\" --run-index \"$SLURM_ARRAY_TASK_ID\"\n"})
    EXPECT_NE(s.find(line), std::string::npos) << line << "\n---\n" << s;
  EXPECT_EQ(s.find("--account"), std::string::npos);
  const std::string c = slurm_collect_script(nine_runs(), o);
  EXPECT_NE(c.find("#SBATCH --job-name=d2gs-llff_fern_3views-collect\n"), std::string::npos) << c;
  EXPECT_NE(c.find("exec \"$D2GS\" experiment collect -o \"$OUT\"\n"), std::string::npos) << c;
  EXPECT_EQ(c.find("--array"), std::string::npos);
  EXPECT_EQ(shell_quote("a'b"), "'a'\\''b'");
  o.partition = "gpu; rm -rf /";
  EXPECT_THROW(slurm_array_script(nine_runs(), 9, o), Error);
}

TEST(Slurm, EmitSlurmWritesScriptsAndTrainsNothing) {
  const auto dir = test::scratch_dir();
  const auto r = test::run_cli("experiment --config '" +
                               (test::source_dir() / "configs/experiments/llff_fern_ablation.json").string() +
                               "' --data-root '" + test::shared_data().string() + "' -o '" + (dir / "exp").string() +
                               "' --emit-slurm --slurm-max-parallel 6");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string s = read_file(dir / "exp/slurm/runs.sbatch");
  EXPECT_NE(s.find("#SBATCH --array=0-17%6\n"), std::string::npos) << s;
  EXPECT_NE(s.find("D2GS='" + test::cli_path().string() + "'"), std::string::npos) << s;
  EXPECT_TRUE(fs::is_regular_file(dir / "exp/slurm/collect.sbatch"));
  EXPECT_TRUE(fs::is_regular_file(dir / "exp/experiment.json"));
  EXPECT_FALSE(fs::exists(dir / "exp/runs"));
  EXPECT_NE(r.output.find("sbatch --dependency=afterany:$jobid"), std::string::npos) << r.output;
  EXPECT_NE(fs::status(dir / "exp/slurm/runs.sbatch").permissions() & fs::perms::owner_exec, fs::perms::none);
  // --run-index outside the list is an error naming the range.
  const auto bad = test::run_cli("experiment -o '" + (dir / "exp").string() + "' --run-index 18");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.output.find("--run-index 18 is outside the experiment's 18 runs"), std::string::npos) << bad.output;
}

}  // namespace
}  // namespace d2gs::experiment
