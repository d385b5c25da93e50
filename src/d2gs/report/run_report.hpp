#pragma once
// The HTML report of one training run (`d2gs report -m RUN`, also written by `d2gs train` and
// `d2gs eval`), and the sections it shares with the experiment report: training curves, test views
// (ground truth | render | error map), Gaussians per depth layer.
#include <filesystem>
#include <string>
#include <vector>

#include "d2gs/report/html.hpp"
#include "d2gs/report/run_data.hpp"

namespace d2gs::report {

struct LabeledRun {
  std::string label;  // e.g. "d2gs" or "d2gs seed 1"
  const RunData* run = nullptr;
};

// Loss (log scale), test PSNR at the logged test iterations and #Gaussians against the iteration, one
// series per run.
std::string curves_html(const std::vector<LabeledRun>& runs);
// For each test view (of the first run that has renders): ground truth, then each run's render and its
// error map. `max_views` < 0: all.
std::string views_html(const std::vector<LabeledRun>& runs, ImageEncoding encoding = ImageEncoding::Jpeg,
                       int max_views = -1);
// Table and bar chart of the Gaussian count per near/middle/far layer.
std::string layers_html(const std::vector<LabeledRun>& runs);

std::string run_report_html(const RunData& run);
// Loads `run_dir` and writes its report (default RUN/report.html) atomically; returns the path written.
std::filesystem::path write_run_report(const std::filesystem::path& run_dir, const std::filesystem::path& out = {});
// The same for the end of `d2gs train` / `d2gs eval`: a failure only warns (the run itself succeeded).
void write_run_report_or_warn(const std::filesystem::path& run_dir);

}  // namespace d2gs::report
