// Tables from run folders: mean ± sample std over seeds, unavailable metrics, averages over scenes, CSV.
#include <cmath>

#include <gtest/gtest.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/experiment/collect.hpp"
#include "d2gs/experiment/tables.hpp"
#include "test_paths.hpp"

namespace d2gs::experiment {
namespace {
namespace fs = std::filesystem;

TEST(Tables, MeanAndSampleStd) {
  const Stat s = mean_std({10.0, 12.0});
  EXPECT_EQ(s.n, 2u);
  EXPECT_DOUBLE_EQ(s.mean, 11.0);
  EXPECT_DOUBLE_EQ(s.std, std::sqrt(2.0));
  EXPECT_EQ(format_stat(s, 2), "11.00 ± 1.41");
  EXPECT_EQ(format_stat(mean_std({0.5}), 3), "0.500");
  EXPECT_EQ(format_stat(mean_std({}), 3), "—");
  EXPECT_EQ(csv_field("a,b"), "\"a,b\"");
  EXPECT_EQ(csv_field("say \"x\""), "\"say \"\"x\"\"\"");
  EXPECT_EQ(csv_field("plain"), "plain");
}

TEST(Tables, ImrCellSaysWhenASolveDidNotConverge) {
  GroupRow row;
  row.label = "d2gs";
  EXPECT_EQ(table_cells(row)[5], "—");
  row.imr = 3.1004;
  EXPECT_EQ(table_cells(row)[5], "3.100");
  row.imr_note = "1 Sinkhorn problem(s) stopped at the iteration limit before converging";
  EXPECT_EQ(table_cells(row)[5], "3.100 (not converged)");
}

// Two scenes × 3 views × (3dgs, d2gs-full) × seeds 0, 1; d2gs has LPIPS, one 3dgs run of scene b is missing.
struct Fixture {
  fs::path dir;
  ExperimentConfig config;
  std::vector<RunSpec> runs;
};

Fixture make_fixture() {
  Fixture f;
  f.dir = test::scratch_dir();
  const nlohmann::json j = {
      {"name", "table test"},
      {"scenes", {{{"name", "a"}, {"source", "/data/a"}}, {{"name", "b"}, {"source", "/data/b"}}}},
      {"views", {3}},
      {"seeds", {0, 1}},
      {"methods", {{{"method", "3dgs"}}, {{"method", "d2gs"}, {"variant", "full"}}}},
      {"imr", {{"enabled", false}}}};
  f.config = parse_experiment_config(j, f.dir / "exp.json");
  f.runs = expand_runs(f.config, f.dir);
  for (const auto& r : f.runs) {
    if (r.scene == "b" && r.label == "3dgs" && r.seed == 1) continue;  // not finished
    const double base = (r.scene == "a" ? 20.0 : 18.0) + (r.label == "3dgs" ? 0.0 : 1.0) + 2.0 * r.seed;
    nlohmann::json res = {{"mean", {{"PSNR", base}, {"SSIM", 0.5 + 0.1 * r.seed}}},
                          {"gaussians", 1000 + 100 * r.seed},
                          {"train_seconds", 10.0},
                          {"lpips", "skipped: no weights"}};
    if (r.label != "3dgs") res["mean"]["LPIPS"] = 0.2 + 0.02 * r.seed;
    write_file_atomic(f.dir / r.dir / "results.json", res.dump());
  }
  return f;
}

// A results.json with values no evaluation gives (SSIM 7, −1 Gaussians) is named, not averaged in.
TEST(Tables, ImpossibleValuesInAResultsFileAreNamed) {
  const Fixture f = make_fixture();
  const fs::path file = f.dir / f.runs[0].dir / "results.json";
  for (const auto& [bad, what] : std::vector<std::pair<nlohmann::json, std::string>>{
           {{{"mean", {{"PSNR", 20.0}, {"SSIM", 7.0}}}}, "SSIM = 7"},
           {{{"mean", {{"PSNR", 20.0}, {"SSIM", 0.5}}}, {"gaussians", -1}}, "GAUSSIANS = -1"},
           {{{"mean", {{"PSNR", 20.0}, {"SSIM", 0.5}, {"LPIPS", -0.1}}}}, "LPIPS = -0.1"}}) {
    write_file_atomic(file, bad.dump());
    try {
      summarize(f.runs, f.dir);
      ADD_FAILURE() << what << " was tabulated";
    } catch (const Error& e) {
      EXPECT_EQ(std::string(e.what()).rfind(file.string() + ": " + what + " is not a value an evaluation gives", 0), 0u)
          << e.what();
    }
  }
}

TEST(Tables, SummariseGroupsBySceneViewsAndMethod) {
  const Fixture f = make_fixture();
  const auto rows = summarize(f.runs, f.dir);
  ASSERT_EQ(rows.size(), 4u);
  EXPECT_EQ(rows[0].scene, "a");
  EXPECT_EQ(rows[0].label, "3dgs");
  EXPECT_EQ(rows[1].label, "d2gs-full");
  EXPECT_EQ(rows[1].variant, "full");
  EXPECT_EQ(rows[0].runs_finished, 2);
  EXPECT_DOUBLE_EQ(rows[0].metrics.at("PSNR").mean, 21.0);
  EXPECT_DOUBLE_EQ(rows[0].metrics.at("PSNR").std, std::sqrt(2.0));
  EXPECT_EQ(rows[0].metrics.count("LPIPS"), 0u);  // a note, not a number
  EXPECT_DOUBLE_EQ(rows[1].metrics.at("LPIPS").mean, 0.21);
  EXPECT_EQ(rows[2].runs_finished, 1);  // b / 3dgs
  EXPECT_EQ(rows[2].runs_total, 2);
  EXPECT_EQ(rows[2].metrics.at("PSNR").n, 1u);

  const std::string md = markdown_tables(rows, "table test");
  EXPECT_NE(md.find("## table test"), std::string::npos);
  EXPECT_NE(md.find("### a, 3 views"), std::string::npos);
  EXPECT_NE(md.find("| 3dgs | 21.00 ± 1.41 | 0.550 ± 0.071 | — | — | — | 1050 ± 71 | 10.0 ± 0.0 | 2/2 |"),
            std::string::npos)
      << md;
  EXPECT_NE(md.find("| d2gs-full | 22.00 ± 1.41 | 0.550 ± 0.071 | 0.210 ± 0.014 |"), std::string::npos) << md;
  EXPECT_NE(md.find("| 3dgs | 18.00 | 0.500 | — | — | — | 1000 | 10.0 | 1/2 |"), std::string::npos) << md;
  // Average over the two scenes: 3dgs (21 + 18) / 2, d2gs (22 + 20) / 2.
  EXPECT_NE(md.find("### mean over 2 scenes, 3 views"), std::string::npos) << md;
  EXPECT_NE(md.find("| 3dgs | 19.50 |"), std::string::npos) << md;
  EXPECT_NE(md.find("| d2gs-full | 21.00 |"), std::string::npos) << md;

  const std::string csv = csv_table(rows);
  std::vector<std::string> lines;
  for (std::size_t p = 0, q; (q = csv.find('\n', p)) != std::string::npos; p = q + 1) lines.push_back(csv.substr(p, q - p));
  ASSERT_EQ(lines.size(), 5u);
  EXPECT_EQ(lines[0].rfind("scene,views,method,variant,label,runs_finished,runs_total,psnr_mean,psnr_std,psnr_n,", 0), 0u);
  EXPECT_EQ(lines[1].rfind("a,3,3dgs,,3dgs,2,2,21,1.41421,2,0.55,0.0707107,2,,,0,,,0,1050,", 0), 0u) << lines[1];
  EXPECT_EQ(lines[2].rfind("a,3,d2gs,full,d2gs-full,2,2,22,", 0), 0u) << lines[2];
  EXPECT_NE(lines[2].find(",0.21,0.0141421,2,"), std::string::npos) << lines[2];
}

TEST(Tables, CollectWritesTablesAndTheExperimentReport) {
  const Fixture f = make_fixture();
  CollectOptions o;
  o.report = true;
  const CollectResult r = collect(f.config, f.runs, f.dir, o);
  EXPECT_EQ(r.finished, 7);
  EXPECT_EQ(r.total, 8);
  EXPECT_EQ(read_file(f.dir / "tables/results.md"), r.markdown);
  EXPECT_TRUE(fs::is_regular_file(f.dir / "tables/results.csv"));
  const std::string html = read_file(f.dir / "report.html");
  for (const char* id : {"tables", "runs", "curves", "views", "layers", "imr"})
    EXPECT_NE(html.find(std::string("<section id=\"") + id + "\">"), std::string::npos) << id;
  EXPECT_NE(html.find("IMR disabled"), std::string::npos);
  EXPECT_NE(html.find("22.00 ± 1.41"), std::string::npos);
  EXPECT_NE(html.find("<td>pending</td>"), std::string::npos);  // b / 3dgs / seed 1
}

}  // namespace
}  // namespace d2gs::experiment
