#include "d2gs/experiment/tables.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <tuple>
#include <set>

#include <fmt/format.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/json_value.hpp"
#include "d2gs/report/run_data.hpp"

namespace d2gs::experiment {
namespace fs = std::filesystem;

namespace {
constexpr const char* kMetrics[] = {"PSNR", "SSIM", "LPIPS", "AVGE"};
int decimals(const std::string& metric) { return metric == "PSNR" ? 2 : 3; }
}  // namespace

Stat mean_std(const std::vector<double>& values) {
  Stat s;
  s.n = values.size();
  if (values.empty()) return s;
  double sum = 0;
  for (double v : values) sum += v;
  s.mean = sum / static_cast<double>(s.n);
  if (s.n > 1) {
    double sq = 0;
    for (double v : values) sq += (v - s.mean) * (v - s.mean);
    s.std = std::sqrt(sq / static_cast<double>(s.n - 1));
  }
  return s;
}

std::string format_stat(const Stat& s, int places) {
  if (s.n == 0) return "—";
  if (s.n == 1) return fmt::format("{:.{}f}", s.mean, places);
  return fmt::format("{:.{}f} ± {:.{}f}", s.mean, places, s.std, places);
}

std::vector<GroupRow> summarize(const std::vector<RunSpec>& runs, const fs::path& out_dir) {
  std::vector<GroupRow> rows;
  std::map<std::tuple<std::string, int, std::string>, std::size_t> where;
  std::map<std::size_t, std::map<std::string, std::vector<double>>> values;
  for (const auto& run : runs) {
    const auto key = std::make_tuple(run.scene, run.views, run.label);
    auto it = where.find(key);
    if (it == where.end()) {
      GroupRow row;
      row.scene = run.scene;
      row.views = run.views;
      row.label = run.label;
      row.method = run.method;
      row.variant = run.variant;
      it = where.emplace(key, rows.size()).first;
      rows.push_back(row);
    }
    GroupRow& row = rows[it->second];
    ++row.runs_total;
    const fs::path results = out_dir / run.dir / "results.json";
    if (!fs::is_regular_file(results)) continue;
    const nlohmann::json j = read_json_file(results);
    ++row.runs_finished;
    auto& v = values[it->second];
    // Values no evaluation gives are not averaged into a table (a hand-edited or foreign results.json).
    const auto take = [&](const std::string& name, double value, double lo, double hi) {
      if (!(value >= lo && value <= hi))
        fail_file(results, "{} = {} is not a value an evaluation gives (expected {} to {})", name, value, lo, hi);
      v[name].push_back(value);
    };
    for (const auto& [name, value] : report::mean_metrics(j)) {
      if (name == "SSIM") take(name, value, -1.0, 1.0);
      else if (name == "LPIPS" || name == "AVGE") take(name, value, 0.0, 1e9);
      else take(name, value, -1e9, 1e9);  // PSNR and others: finite
    }
    if (j.contains("gaussians") && j["gaussians"].is_number()) take("GAUSSIANS", j["gaussians"].get<double>(), 0.0, 1e12);
    if (j.contains("train_seconds") && j["train_seconds"].is_number())
      take("TRAIN_SECONDS", j["train_seconds"].get<double>(), 0.0, 1e12);
  }
  for (auto& [index, metrics] : values)
    for (auto& [name, list] : metrics) rows[index].metrics[name] = mean_std(list);
  return rows;
}

std::vector<std::string> table_header() {
  return {"method", "PSNR ↑", "SSIM ↑", "LPIPS ↓", "AVGE ↓", "IMR ↓", "#Gaussians", "time (s)", "runs"};
}

std::vector<std::string> table_cells(const GroupRow& row) {
  std::vector<std::string> cells = {row.label};
  const auto stat = [&](const char* key, int places) {
    const auto it = row.metrics.find(key);
    return it == row.metrics.end() ? std::string("—") : format_stat(it->second, places);
  };
  for (const char* m : kMetrics) cells.push_back(stat(m, decimals(m)));
  // With a value, a note can only say that a Sinkhorn problem stopped before converging.
  cells.push_back(row.imr ? fmt::format("{:.3f}{}", *row.imr, row.imr_note.empty() ? "" : " (not converged)") : "—");
  cells.push_back(stat("GAUSSIANS", 0));
  cells.push_back(stat("TRAIN_SECONDS", 1));
  cells.push_back(fmt::format("{}/{}", row.runs_finished, row.runs_total));
  return cells;
}

namespace {

std::string markdown_table(const std::vector<std::vector<std::string>>& rows) {
  const auto header = table_header();
  std::string out = "|";
  for (const auto& h : header) out += " " + h + " |";
  out += "\n|";
  for (std::size_t i = 0; i < header.size(); ++i) out += i == 0 ? "---|" : "---:|";
  out += "\n";
  for (const auto& r : rows) {
    out += "|";
    for (const auto& c : r) {
      std::string cell = c;
      for (std::size_t p = 0; (p = cell.find('|', p)) != std::string::npos; p += 2) cell.replace(p, 1, "\\|");
      out += " " + cell + " |";
    }
    out += "\n";
  }
  return out;
}

}  // namespace

std::string markdown_tables(const std::vector<GroupRow>& rows, const std::string& title) {
  std::string out = "## " + title + "\n\n";
  out += "Mean ± sample standard deviation over the finished seeds; IMR over the seeds' models (lower is more "
         "stable); — = not available.\n";
  std::vector<std::pair<std::string, int>> groups;
  std::set<std::string> scenes;
  std::vector<int> views;
  for (const auto& r : rows) {
    const auto g = std::make_pair(r.scene, r.views);
    if (std::find(groups.begin(), groups.end(), g) == groups.end()) groups.push_back(g);
    scenes.insert(r.scene);
    if (std::find(views.begin(), views.end(), r.views) == views.end()) views.push_back(r.views);
  }
  for (const auto& [scene, v] : groups) {
    out += fmt::format("\n### {}, {} views\n\n", scene, v == 0 ? std::string("all") : std::to_string(v));
    std::vector<std::vector<std::string>> cells;
    for (const auto& r : rows)
      if (r.scene == scene && r.views == v) cells.push_back(table_cells(r));
    out += markdown_table(cells);
  }
  if (scenes.size() > 1)
    for (int v : views) {
      // Average over scenes of the per-scene means (the paper's dataset rows).
      std::vector<std::string> labels;
      for (const auto& r : rows)
        if (r.views == v && std::find(labels.begin(), labels.end(), r.label) == labels.end()) labels.push_back(r.label);
      std::vector<std::vector<std::string>> cells;
      for (const auto& label : labels) {
        GroupRow avg;
        avg.label = label;
        std::map<std::string, std::vector<double>> means;
        std::vector<double> imrs;
        int scenes_with = 0;
        for (const auto& r : rows) {
          if (r.views != v || r.label != label) continue;
          avg.runs_total += r.runs_total;
          avg.runs_finished += r.runs_finished;
          if (r.runs_finished > 0) ++scenes_with;
          for (const auto& [name, s] : r.metrics)
            if (s.n > 0) means[name].push_back(s.mean);
          if (r.imr) imrs.push_back(*r.imr);
        }
        for (const auto& [name, list] : means) {
          Stat s = mean_std(list);
          s.n = 1;  // a mean of means: no seed spread to show
          avg.metrics[name] = s;
        }
        if (!imrs.empty()) avg.imr = mean_std(imrs).mean;
        auto c = table_cells(avg);
        if (scenes_with < static_cast<int>(scenes.size()))
          c[0] += fmt::format(" ({} of {} scenes)", scenes_with, scenes.size());
        cells.push_back(c);
      }
      out += fmt::format("\n### mean over {} scenes, {} views\n\n", scenes.size(),
                         v == 0 ? std::string("all") : std::to_string(v));
      out += markdown_table(cells);
    }
  return out;
}

std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

std::string csv_table(const std::vector<GroupRow>& rows) {
  std::string out = "scene,views,method,variant,label,runs_finished,runs_total";
  const char* columns[] = {"PSNR", "SSIM", "LPIPS", "AVGE", "GAUSSIANS", "TRAIN_SECONDS"};
  for (const char* c : columns) {
    std::string lower = c;
    for (char& ch : lower) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    out += fmt::format(",{0}_mean,{0}_std,{0}_n", lower);
  }
  out += ",imr\n";
  for (const auto& r : rows) {
    out += fmt::format("{},{},{},{},{},{},{}", csv_field(r.scene), r.views, csv_field(r.method), csv_field(r.variant),
                       csv_field(r.label), r.runs_finished, r.runs_total);
    for (const char* c : columns) {
      const auto it = r.metrics.find(c);
      if (it == r.metrics.end() || it->second.n == 0) out += ",,,0";
      else out += fmt::format(",{:.6g},{:.6g},{}", it->second.mean, it->second.std, it->second.n);
    }
    out += r.imr ? fmt::format(",{:.6g}\n", *r.imr) : std::string(",\n");
  }
  return out;
}

}  // namespace d2gs::experiment
