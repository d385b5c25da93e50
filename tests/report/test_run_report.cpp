// Run data and the per-run report: training log (resumed runs), metrics (LPIPS present or not),
// depth-layer counts, the page's content, the `d2gs report` command and the report written by train/eval.
#include <fstream>

#include <gtest/gtest.h>

#include "d2gs/core/error.hpp"
#include "d2gs/report/run_report.hpp"
#include "fake_run.hpp"
#include "test_paths.hpp"

namespace d2gs::report {
namespace {
namespace fs = std::filesystem;

using test::count_occurrences;

TEST(RunData, TrainLogOfAResumedRunKeepsTheLastRecordOfEachIteration) {
  const auto dir = test::scratch_dir();
  std::ofstream(dir / "log.jsonl") << R"({"iteration":10,"loss":0.5,"gaussians":100,"elapsed_s":1}
{"iteration":20,"loss":0.4,"gaussians":110,"elapsed_s":2}
{"event":"test","iteration":20,"psnr":14,"ssim":0.4}
{"iteration":30,"loss":0.3,"gaussians":120,"elapsed_s":3}
{"event":"densify","iteration":30,"added":5}
{"iteration":20,"loss":0.41,"gaussians":111,"elapsed_s":2.5}
{"event":"test","iteration":20,"psnr":14.1,"ssim":0.41}
{"iteration":30,"loss":0.31,"gaussians":121,"elapsed_s":3.5}
{"iteration":40,"loss":0.2,"gaus)";
  const TrainLog log = read_train_log(dir / "log.jsonl");
  EXPECT_EQ(log.iteration, (std::vector<double>{10, 20, 30}));
  EXPECT_EQ(log.loss, (std::vector<double>{0.5, 0.41, 0.31}));
  EXPECT_EQ(log.gaussians, (std::vector<double>{100, 111, 121}));
  EXPECT_EQ(log.test_iteration, (std::vector<double>{20}));
  EXPECT_EQ(log.test_psnr, (std::vector<double>{14.1}));
  std::ofstream(dir / "bad.jsonl") << "{\"iteration\":1}\nnot json\n{\"iteration\":2}\n";
  try {
    read_train_log(dir / "bad.jsonl");
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.jsonl: line 2"), std::string::npos) << e.what();
  }
}

TEST(RunData, MetricsTakeOnlyNumbersAndKnowTheirDirection) {
  const nlohmann::json without = {{"mean", {{"PSNR", 20.0}, {"SSIM", 0.7}}}, {"lpips", "skipped: no weights"}};
  EXPECT_EQ(mean_metrics(without), (Metrics{{"PSNR", 20.0}, {"SSIM", 0.7}}));
  const nlohmann::json with = {{"mean", {{"PSNR", 20.0}, {"SSIM", 0.7}, {"lpips", 0.2}}}, {"avge", 0.1}};
  EXPECT_EQ(mean_metrics(with), (Metrics{{"PSNR", 20.0}, {"SSIM", 0.7}, {"LPIPS", 0.2}, {"AVGE", 0.1}}));
  EXPECT_EQ(metric_order({"SSIM", "AVGE", "X", "PSNR", "LPIPS"}),
            (std::vector<std::string>{"PSNR", "SSIM", "LPIPS", "AVGE", "X"}));
  EXPECT_TRUE(lower_is_better("lpips"));
  EXPECT_TRUE(lower_is_better("IMR"));
  EXPECT_FALSE(lower_is_better("PSNR"));
}

TEST(RunData, CountsGaussiansPerDepthLayerOfTheInitialCloud) {
  const auto dir = test::scratch_dir() / "run";
  test::make_fake_run(dir);
  const RunData run = load_run(dir);
  EXPECT_EQ(run.iteration, 30);
  EXPECT_EQ(run.method(), "d2gs");
  ASSERT_EQ(run.views.size(), 2u);
  EXPECT_EQ(run.views[0].name, "image0");
  ASSERT_TRUE(run.layers.has_value()) << run.layers_note;
  EXPECT_EQ(run.layers->near, 2u);
  EXPECT_EQ(run.layers->middle, 3u);
  EXPECT_EQ(run.layers->far, 2u);
  EXPECT_EQ(run.layers->behind, 1u);
  EXPECT_DOUBLE_EQ(run.layers->near_limit, 3.0);
  EXPECT_DOUBLE_EQ(run.layers->far_limit, 7.0);
  EXPECT_NE(run.layers->camera.find("image0"), std::string::npos);  // the first test view
  EXPECT_NE(run.layers->boundary.find("input.ply"), std::string::npos);
}

TEST(RunReport, PageHasEverySectionEmbeddedImagesAndEscapedNames) {
  const auto dir = test::scratch_dir() / "run <a&b>";
  test::make_fake_run(dir, "dropgaussian");
  // A killed writer's temporary among the renders (truncated) is no test view of the report.
  const fs::path renders = load_run(dir).views.at(0).render.parent_path();
  write_file_atomic(renders / ".view0.tmp4000000-0.png", "\x89PNG truncated");
  ASSERT_EQ(load_run(dir).views.size(), 2u);
  const fs::path out = write_run_report(dir);
  EXPECT_EQ(out, dir / "report.html");
  const std::string html = read_file(out);
  EXPECT_EQ(test::check_balanced(html), "");
  for (const char* id : {"summary", "metrics", "curves", "views", "layers", "imr"})
    EXPECT_NE(html.find(std::string("<section id=\"") + id + "\">"), std::string::npos) << id;
  EXPECT_NE(html.find("run &lt;a&amp;b&gt;"), std::string::npos);
  EXPECT_EQ(html.find("run <a&b>"), std::string::npos);
  // 2 views × (ground truth, render, error map), all embedded
  EXPECT_EQ(count_occurrences(html, "<img src=\"data:image/jpeg;base64,"), 6u);
  EXPECT_EQ(count_occurrences(html, "<img "), 6u);
  EXPECT_EQ(count_occurrences(html, "<svg "), 4u);  // loss, PSNR, #Gaussians, layers
  EXPECT_NE(html.find("15.25"), std::string::npos);            // mean PSNR
  EXPECT_NE(html.find("dropgaussian · 15.00 dB"), std::string::npos);
  EXPECT_NE(html.find("Unavailable in results.json: LPIPS, AVGE"), std::string::npos);
  EXPECT_NE(html.find("2 (25 %)"), std::string::npos);  // near layer
  // With LPIPS in results.json the table shows it.
  const auto dir2 = test::scratch_dir() / "with_lpips";
  test::make_fake_run(dir2, "d2gs", {{"mean", {{"PSNR", 15.25}, {"SSIM", 0.5}, {"LPIPS", 0.1875}}}});
  const std::string html2 = run_report_html(load_run(dir2));
  EXPECT_NE(html2.find("LPIPS ↓"), std::string::npos);
  EXPECT_NE(html2.find("0.1875"), std::string::npos);
}

TEST(RunReport, UnfinishedRunStillReportsAndNonRunIsAnError) {
  const auto dir = test::scratch_dir();
  test::make_fake_run(dir / "run");
  fs::remove(dir / "run/results.json");
  fs::remove_all(dir / "run/test");
  const std::string html = run_report_html(load_run(dir / "run"));
  EXPECT_NE(html.find("No results.json"), std::string::npos);
  EXPECT_NE(html.find("No test renders"), std::string::npos);
  fs::create_directories(dir / "empty");
  try {
    load_run(dir / "empty");
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("empty: not a run folder"), std::string::npos) << e.what();
  }
}

// Recorded files whose values have another JSON type than d2gs writes: one line naming the file and the
// key, not the JSON library's internal message.
TEST(ReportCli, MistypedValuesInTheRunsFilesNameTheFileAndTheKey) {
  const auto dir = test::scratch_dir();
  const auto report = [&](const std::string& name) {
    return test::run_cli("report -m '" + (dir / name).string() + "' -o '" + (dir / (name + ".html")).string() + "'");
  };
  const auto expect_error = [&](const std::string& name, const std::string& message) {
    const auto r = report(name);
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_NE(r.output.find("d2gs: error: " + (dir / name).string() + "/" + message), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find("internal"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(dir / (name + ".html")));
  };
  const auto edit_config = [&](const std::string& name, const char* key, const nlohmann::json& value) {
    test::make_fake_run(dir / name);
    nlohmann::json c = nlohmann::json::parse(read_file(dir / name / "config.json"));
    c[key] = value;
    std::ofstream(dir / name / "config.json") << c.dump();
  };
  edit_config("names", "split", {{"train", {1, 2}}, {"test", {"a", "b"}}});
  expect_error("names", "config.json: key 'split.test[0]' must be an integer");
  edit_config("number", "split", {{"train", {1, 2}}, {"test", 5}});
  expect_error("number", "config.json: key 'split.test' must be a list of numbers");
  test::make_fake_run(dir / "cameras");
  std::ofstream(dir / "cameras/cameras.json") << "[1, 2, 3]";
  expect_error("cameras", "cameras.json: camera entry 0 is not an object");
  test::make_fake_run(dir / "loss");
  std::ofstream(dir / "loss/train_log.jsonl") << "{\"iteration\":1,\"loss\":\"abc\"}\n{\"iteration\":2}\n";
  expect_error("loss", "train_log.jsonl: line 1: 'loss' must be a number");
  test::make_fake_run(dir / "event");
  std::ofstream(dir / "event/train_log.jsonl") << "{\"iteration\":1,\"event\":7}\n{\"iteration\":2}\n";
  expect_error("event", "train_log.jsonl: line 1: 'event' must be a string");
  test::make_fake_run(dir / "results");
  fs::remove(dir / "results/results.json");
  std::ofstream(dir / "results/results.json") << "{\"mean\": 5}";
  expect_error("results", "results.json: key 'mean' must be an object, got 5");
  test::make_fake_run(dir / "results_list");
  fs::remove(dir / "results_list/results.json");
  std::ofstream(dir / "results_list/results.json") << "[]";
  expect_error("results_list", "results.json: is not a JSON object of results");
  // A split that is no object and an oracle flag that is no boolean are shown as unknown, not an error.
  edit_config("odd", "split", 3);
  nlohmann::json c = nlohmann::json::parse(read_file(dir / "odd/config.json"));
  c["init_is_oracle"] = "yes";
  std::ofstream(dir / "odd/config.json") << c.dump();
  const auto odd = report("odd");
  EXPECT_EQ(odd.exit_code, 0) << odd.output;
}

TEST(ReportCli, WritesTheReportAndRejectsAFolderThatIsNoRun) {
  const auto dir = test::scratch_dir();
  test::make_fake_run(dir / "run");
  const auto r = test::run_cli("report -m '" + (dir / "run").string() + "' -o '" + (dir / "out.html").string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(read_file(dir / "out.html").find("<section id=\"views\">"), std::string::npos);
  // Run again: its own page is replaced. Anything else given as -o is not (the run's config.json, a user's file).
  const auto again = test::run_cli("report -m '" + (dir / "run").string() + "' -o '" + (dir / "out.html").string() + "'");
  EXPECT_EQ(again.exit_code, 0) << again.output;
  const std::string config = read_file(dir / "run/config.json");
  for (const fs::path& victim : {dir / "run/config.json", dir / "notes.html"}) {
    if (!fs::exists(victim)) std::ofstream(victim) << "<html>my notes</html>";
    const std::string before = read_file(victim);
    const auto r2 = test::run_cli("report -m '" + (dir / "run").string() + "' -o '" + victim.string() + "'");
    EXPECT_EQ(r2.exit_code, 1) << r2.output;
    EXPECT_NE(r2.output.find(victim.string() + ": exists and is not a d2gs report"), std::string::npos) << r2.output;
    EXPECT_EQ(read_file(victim), before);
  }
  EXPECT_EQ(read_file(dir / "run/config.json"), config);
  const auto bad = test::run_cli("report -m '" + (dir / "nothing").string() + "'");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.output.find("d2gs: error: "), std::string::npos) << bad.output;
  EXPECT_NE(bad.output.find("no such run folder"), std::string::npos) << bad.output;
}

TEST(ReportCli, TrainAndEvalWriteTheRunReport) {
  const auto dir = test::scratch_dir();
  const auto fern = test::shared_data() / "nerf_llff_data/fern";
  const auto r = test::run_cli("train -s '" + fern.string() + "' -m '" + (dir / "run").string() +
                               "' -r 8 --n-views 3 --iterations 3 --init sfm-all-views --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string html = read_file(dir / "run/report.html");
  EXPECT_EQ(count_occurrences(html, "<img src=\"data:image/jpeg;base64,"), 9u);  // fern: 3 test views
  EXPECT_NE(html.find("ORACLE"), std::string::npos);                   // sfm-all-views init is labelled
  fs::remove(dir / "run/report.html");
  const auto e = test::run_cli("eval -m '" + (dir / "run").string() + "'");
  ASSERT_EQ(e.exit_code, 0) << e.output;
  EXPECT_TRUE(fs::is_regular_file(dir / "run/report.html"));
}

}  // namespace
}  // namespace d2gs::report
