#pragma once
// The paper-style tables of an experiment: one row per method (or ablation variant) and (scene, view
// count), metrics as mean ± sample standard deviation over the finished seeds, IMR over the seeds'
// models. Markdown for people, CSV (one row per group, every number in its own column) for tools.
#include <cstddef>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "d2gs/experiment/experiment_config.hpp"

namespace d2gs::experiment {

struct Stat {
  std::size_t n = 0;
  double mean = 0, std = 0;  // std: sample standard deviation (n − 1); 0 for one value
};
Stat mean_std(const std::vector<double>& values);
// "19.22 ± 0.10" (n ≥ 2), "19.22" (n = 1), "—" (n = 0).
std::string format_stat(const Stat& s, int decimals);

struct GroupRow {
  std::string scene;
  int views = 0;
  std::string label, method, variant;
  int runs_total = 0, runs_finished = 0;
  std::map<std::string, Stat> metrics;  // PSNR, SSIM, LPIPS, AVGE (when present), GAUSSIANS, TRAIN_SECONDS
  std::optional<double> imr;
  std::string imr_note;  // why IMR is missing, or (with a value) that a Sinkhorn problem did not converge
};

// Reads results.json of every finished run and groups them (order: scene, views, then the methods'
// order in the experiment). IMR is filled in separately (collect.hpp).
std::vector<GroupRow> summarize(const std::vector<RunSpec>& runs, const std::filesystem::path& out_dir);

// Column titles and formatted cells of a row, as in the paper's tables (LPIPS/AVGE "—" when absent).
std::vector<std::string> table_header();
std::vector<std::string> table_cells(const GroupRow& row);

// "## <title>" then one table per (scene, views), and per view count an average over scenes when there is
// more than one scene.
std::string markdown_tables(const std::vector<GroupRow>& rows, const std::string& title);
std::string csv_table(const std::vector<GroupRow>& rows);
// A CSV field, quoted when it holds a comma, quote or line break.
std::string csv_field(const std::string& s);

}  // namespace d2gs::experiment
