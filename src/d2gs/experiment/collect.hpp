#pragma once
// Collecting an experiment: metrics of every finished run, IMR per (scene, views, method) over its
// seeds, the tables (DIR/tables/results.{md,csv}) and the experiment's HTML report (DIR/report.html).
// Works on a folder filled by any number of runners (local jobs or a Slurm array).
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "d2gs/experiment/experiment_config.hpp"
#include "d2gs/experiment/tables.hpp"

namespace d2gs::experiment {

struct CollectOptions {
  bool imr = true;     // compute IMR (also needs the experiment's "imr.enabled")
  bool report = true;  // write DIR/report.html (and missing per-run report.html)
  std::function<void(const std::string&)> progress;
};

struct CollectResult {
  std::vector<GroupRow> rows;
  std::string markdown;
  std::filesystem::path markdown_path, csv_path, report_path;
  int finished = 0, total = 0;
};

CollectResult collect(const ExperimentConfig& config, const std::vector<RunSpec>& runs,
                      const std::filesystem::path& out_dir, const CollectOptions& options = {});

// The HTML report of an experiment (tables, run status, curves, test views, depth layers, IMR).
std::string experiment_report_html(const ExperimentConfig& config, const std::vector<RunSpec>& runs,
                                   const std::filesystem::path& out_dir, const std::vector<GroupRow>& rows);

}  // namespace d2gs::experiment
