// `d2gs eval` with and without LPIPS weights: results.json, the table, the input-range label, AVGE, errors.
#include <algorithm>
#include <cstdlib>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/eval/evaluate.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {
namespace fs = std::filesystem;

fs::path weights() { return test::source_dir() / "tests/eval/fixtures/lpips/vgg16_w8.safetensors"; }

// A few iterations on fern at 1/8 resolution: enough for a run folder that d2gs eval takes.
fs::path tiny_run(const fs::path& dir) {
  const auto run = dir / "run";
  const auto r = test::run_cli(fmt::format(
      "-q train -s '{}' -m '{}' -r 8 --n-views 3 --iterations 3 --init random --random-points 1500",
      (test::shared_data() / "nerf_llff_data/fern").string(), run.string()));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  return run;
}

TEST(EvalLpipsCli, WithoutWeightsLpipsIsSkippedAndAvgeIsNull) {
  const auto run = tiny_run(test::scratch_dir());
  ::unsetenv("D2GS_LPIPS_WEIGHTS");
  const auto e = test::run_cli(fmt::format("eval -m '{}'", run.string()));
  ASSERT_EQ(e.exit_code, 0) << e.output;
  EXPECT_NE(e.output.find("LPIPS skipped: no LPIPS weights given"), std::string::npos) << e.output;
  EXPECT_NE(e.output.find("AVGE unavailable"), std::string::npos) << e.output;
  const auto j = nlohmann::json::parse(read_file(run / "results.json"));
  EXPECT_EQ(j["lpips"]["status"], "skipped");
  EXPECT_TRUE(j["mean"]["LPIPS"].is_null());
  EXPECT_TRUE(j["mean"]["AVGE"].is_null());
  for (const auto& [name, v] : j["per_view"].items()) {
    EXPECT_TRUE(v["LPIPS"].is_null()) << name;
    EXPECT_TRUE(v["AVGE"].is_null()) << name;
    EXPECT_TRUE(v["PSNR"].is_number()) << name;
  }
}

TEST(EvalLpipsCli, WithWeightsEveryViewHasLpipsAndAvgeLabelledByInputRange) {
  const auto run = tiny_run(test::scratch_dir());
  ::unsetenv("D2GS_LPIPS_WEIGHTS");
  nlohmann::json by_range;
  for (const std::string range : {"unit", "symmetric"}) {
    const auto e = test::run_cli(fmt::format("eval -m '{}' --lpips-weights '{}' --lpips-input-range {}", run.string(),
                                             weights().string(), range));
    ASSERT_EQ(e.exit_code, 0) << e.output;
    EXPECT_NE(e.output.find(range == "unit" ? "input [0,1] (unit)" : "input [-1,1] (symmetric)"), std::string::npos) << e.output;
    EXPECT_NE(e.output.find("vgg16 (taps 8, 16, 32, 64, 64)"), std::string::npos) << e.output;
    const auto j = nlohmann::json::parse(read_file(run / "results.json"));
    EXPECT_EQ(j["lpips"]["status"], "computed");
    EXPECT_EQ(j["lpips"]["input_range"], range);
    EXPECT_EQ(j["lpips"]["weights"], weights().string());
    ASSERT_EQ(j["per_view"].size(), 3u);
    double lpips_sum = 0, avge_sum = 0;
    for (const auto& [name, v] : j["per_view"].items()) {
      const double l = v["LPIPS"], a = v["AVGE"];
      EXPECT_GT(l, 0.0) << name;
      EXPECT_NEAR(a, avge(v["PSNR"], v["SSIM"], l), 1e-12) << name;
      lpips_sum += l;
      avge_sum += a;
    }
    EXPECT_NEAR(j["mean"]["LPIPS"].get<double>(), lpips_sum / 3, 1e-12);
    EXPECT_NEAR(j["mean"]["AVGE"].get<double>(), avge_sum / 3, 1e-12);
    by_range[range] = j["mean"]["LPIPS"];
  }
  EXPECT_NE(by_range["unit"], by_range["symmetric"]);
  // The environment default serves when no option is given.
  ::setenv("D2GS_LPIPS_WEIGHTS", weights().c_str(), 1);
  const auto e = test::run_cli(fmt::format("-q eval -m '{}' --json", run.string()));
  ::unsetenv("D2GS_LPIPS_WEIGHTS");
  ASSERT_EQ(e.exit_code, 0) << e.output;
  const auto j = nlohmann::json::parse(read_file(run / "results.json"));
  EXPECT_EQ(j["mean"]["LPIPS"], by_range["unit"]);
}

TEST(EvalLpipsCli, BadWeightsOrRangeFailWithOneLine) {
  const auto dir = test::scratch_dir();
  const auto run = tiny_run(dir);
  ::unsetenv("D2GS_LPIPS_WEIGHTS");
  write_file_atomic(dir / "junk.safetensors", "this is not a weights file");
  for (const auto& w : {dir / "junk.safetensors", dir / "missing.safetensors"}) {
    const auto e = test::run_cli(fmt::format("eval -m '{}' --lpips-weights '{}'", run.string(), w.string()));
    EXPECT_EQ(e.exit_code, 1) << e.output;
    EXPECT_EQ(e.output.rfind("d2gs: error: " + w.string(), 0), 0u) << e.output;
    EXPECT_EQ(std::count(e.output.begin(), e.output.end(), '\n'), 1) << e.output;  // one line
  }
  const auto e = test::run_cli(fmt::format("eval -m '{}' --lpips-weights '{}' --lpips-input-range 0-255", run.string(),
                                           weights().string()));
  EXPECT_EQ(e.exit_code, 1) << e.output;
  EXPECT_NE(e.output.find("--lpips-input-range"), std::string::npos) << e.output;
}

}  // namespace
}  // namespace d2gs
