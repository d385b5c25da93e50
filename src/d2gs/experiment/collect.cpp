#include "d2gs/experiment/collect.hpp"

#include <algorithm>
#include <memory>

#include <unistd.h>

#include <fmt/format.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/eval/imr.hpp"
#include "d2gs/experiment/run_state.hpp"
#include "d2gs/model/ply.hpp"
#include "d2gs/report/html.hpp"
#include "d2gs/report/run_report.hpp"
#include "d2gs/scene/scene.hpp"

namespace d2gs::experiment {
namespace fs = std::filesystem;

namespace {

// The highest point_cloud/iteration_N/point_cloud.ply of a run, or empty.
fs::path final_ply(const fs::path& run_dir) {
  const report::RunData r = report::load_run(run_dir, {false});
  return r.ply;
}

std::string group_key(const GroupRow& g) { return fmt::format("{}__{}v__{}", g.scene, g.views, g.label); }

// IMR of one group, cached in DIR/imr/<key>.json (recomputed when the models or the settings change).
void group_imr(GroupRow& row, const std::vector<const RunSpec*>& members, const fs::path& out_dir,
               const ExperimentConfig& config, const CollectOptions& options) {
  std::vector<fs::path> plys;
  nlohmann::json identity = nlohmann::json::array();
  for (const RunSpec* r : members) {
    if (!fs::is_regular_file(out_dir / r->dir / "results.json")) continue;
    const fs::path ply = final_ply(out_dir / r->dir);
    if (ply.empty()) continue;
    plys.push_back(ply);
    identity.push_back({{"ply", fs::relative(ply, out_dir).string()}, {"bytes", fs::file_size(ply)},
                        {"mtime", fs::last_write_time(ply).time_since_epoch().count()}});
  }
  if (plys.size() < 2) {
    row.imr_note = fmt::format("needs 2 finished seeds, has {}", plys.size());
    return;
  }
  ImrOptions o;
  o.mixture.samples = config.imr_samples;
  // The default of d2gs imr: stabilised-kernel iterations, Anderson, ε ÷4 (docs/benchmarks.md).
  const nlohmann::json solver = {{"epsilon", o.sinkhorn.epsilon},
                                 {"tolerance", o.sinkhorn.tolerance},
                                 {"max_iterations", o.sinkhorn.max_iterations},
                                 {"epsilon_scaling", o.sinkhorn.epsilon_scaling},
                                 {"epsilon_factor", o.sinkhorn.epsilon_factor},
                                 {"stage_tolerance", o.sinkhorn.stage_tolerance},
                                 {"anderson_depth", o.sinkhorn.anderson_depth},
                                 {"anderson_max_restarts", o.sinkhorn.anderson_max_restarts},
                                 {"solver", to_string(o.sinkhorn.method)},
                                 {"revision", kSinkhornRevision}};
  const auto note_unconverged = [&row](const nlohmann::json& pairs) {
    int unconverged = 0;
    for (const auto& p : pairs) unconverged += p.at("converged").get<bool>() ? 0 : 1;
    if (unconverged > 0)
      row.imr_note = fmt::format("{} Sinkhorn problem(s) stopped at the iteration limit before converging", unconverged);
  };
  const fs::path cache = out_dir / "imr" / (group_key(row) + ".json");
  if (fs::is_regular_file(cache)) {
    try {
      const auto j = nlohmann::json::parse(read_file(cache));
      if (j.at("models") == identity && j.at("samples") == nlohmann::json(config.imr_samples) &&
          j.at("solver") == solver) {
        row.imr = j.at("imr").get<double>();
        note_unconverged(j.at("pairs"));
        return;
      }
    } catch (const nlohmann::json::exception&) {
      // stale or damaged cache: recompute
    }
  }
  const nlohmann::json& tc = members.front()->train_config;
  SceneLoadOptions load;
  load.resolution = tc.at("resolution").get<int>();
  const Scene scene = load_scene(tc.at("source").get<std::string>(), load);
  if (scene.cameras.empty()) fail_file(tc.at("source").get<std::string>(), "scene has no cameras");
  const Camera& reference = scene.cameras.front();  // the release: image 0, the first test view
  std::vector<GaussianMixture> mixtures;
  for (const auto& p : plys) mixtures.push_back(mixture_from_model(read_gaussians_ply(p), reference, o.mixture));
  if (options.progress)
    options.progress(fmt::format("IMR of {} ({} models, {} samples)...", group_key(row), plys.size(), config.imr_samples));
  const ImrResult result = compute_imr(mixtures, o);
  row.imr = result.imr;
  nlohmann::json pairs = nlohmann::json::array();
  for (const auto& p : result.pairs)
    pairs.push_back({{"a", p.a},
                     {"b", p.b},
                     {"distance", p.distance},
                     {"iterations", p.transport.iterations},
                     {"seconds", p.transport.seconds},
                     {"converged", p.transport.converged}});
  note_unconverged(pairs);
  const nlohmann::json out = {{"models", identity},
                              {"samples", config.imr_samples},
                              {"solver", solver},
                              {"reference_camera", reference.image_name},
                              {"imr", result.imr},
                              {"pairs", pairs}};
  write_file_atomic(cache, out.dump(2) + "\n");
}

}  // namespace

CollectResult collect(const ExperimentConfig& config, const std::vector<RunSpec>& runs, const fs::path& out_dir,
                      const CollectOptions& options) {
  CollectResult result;
  result.rows = summarize(runs, out_dir);
  result.total = static_cast<int>(runs.size());
  for (const auto& r : runs)
    if (fs::is_regular_file(out_dir / r.dir / "results.json")) ++result.finished;
  for (auto& row : result.rows) {
    std::vector<const RunSpec*> members;
    for (const auto& r : runs)
      if (r.scene == row.scene && r.views == row.views && r.label == row.label) members.push_back(&r);
    if (!(options.imr && config.imr_enabled)) {
      row.imr_note = "IMR disabled";
      continue;
    }
    try {
      group_imr(row, members, out_dir, config, options);
    } catch (const Error& e) {
      row.imr_note = e.what();
      if (options.progress) options.progress(fmt::format("IMR of {}: {}", group_key(row), e.what()));
    }
  }
  result.markdown = markdown_tables(result.rows, config.name);
  result.markdown_path = out_dir / "tables" / "results.md";
  result.csv_path = out_dir / "tables" / "results.csv";
  write_file_atomic(result.markdown_path, result.markdown);
  write_file_atomic(result.csv_path, csv_table(result.rows));
  if (options.report) {
    for (const auto& r : runs) {
      const fs::path dir = out_dir / r.dir;
      if (fs::is_regular_file(dir / "results.json") && !fs::is_regular_file(dir / "report.html")) {
        try {
          report::write_run_report(dir);
        } catch (const Error& e) {
          if (options.progress) options.progress(fmt::format("report of {}: {}", r.id(), e.what()));
        }
      }
    }
    result.report_path = out_dir / "report.html";
    write_file_atomic(result.report_path, experiment_report_html(config, runs, out_dir, result.rows));
  }
  return result;
}

std::string experiment_report_html(const ExperimentConfig& config, const std::vector<RunSpec>& runs,
                                   const fs::path& out_dir, const std::vector<GroupRow>& rows) {
  using report::html_escape;
  int finished = 0;
  for (const auto& r : runs) finished += fs::is_regular_file(out_dir / r.dir / "results.json") ? 1 : 0;
  report::HtmlPage page("d2gs experiment: " + config.name,
                        fmt::format("{} of {} runs finished · {}", finished, runs.size(), out_dir.string()));

  // Tables, one per (scene, views), the same cells as results.md.
  std::string tables;
  if (!config.description.empty()) tables += "<p>" + html_escape(config.description) + "</p>\n";
  std::vector<std::pair<std::string, int>> groups;
  for (const auto& r : rows)
    if (std::find(groups.begin(), groups.end(), std::make_pair(r.scene, r.views)) == groups.end())
      groups.emplace_back(r.scene, r.views);
  for (const auto& [scene, v] : groups) {
    std::vector<std::vector<std::string>> cells;
    for (const auto& r : rows)
      if (r.scene == scene && r.views == v) cells.push_back(table_cells(r));
    tables += fmt::format("<h3>{}, {} views</h3>\n", html_escape(scene), v == 0 ? std::string("all") : std::to_string(v));
    tables += report::html_table(table_header(), cells);
  }
  tables += "<p class=\"note\">Mean ± sample standard deviation over the finished seeds; — = not available "
            "(LPIPS/AVGE appear when results.json has them). Also in tables/results.md and tables/results.csv.</p>\n";
  page.add_section("tables", "Results", tables);

  // Run status: what `d2gs experiment --list` says (run_state.hpp).
  std::vector<std::vector<std::string>> status_rows;
  for (const auto& r : runs) {
    const RunState state = inspect_run(out_dir, r, static_cast<long>(::getpid()));  // our runs have ended
    std::string status = describe(state);
    if (state.phase == RunPhase::Failed || state.phase == RunPhase::Interrupted)
      status += " (see logs/" + r.id() + ".log)";
    const bool scored = state.phase == RunPhase::Finished && state.message.empty();
    status_rows.push_back({std::to_string(r.index), r.scene, std::to_string(r.views), r.label,
                           std::to_string(r.seed), status, scored ? fmt::format("{:.2f}", state.psnr) : "—"});
  }
  page.add_section("runs", "Runs",
                   report::html_table({"#", "scene", "views", "method", "seed", "status", "PSNR"}, status_rows, 6));

  // Per (scene, views): the first finished seed of every method.
  std::string curves, views, layers;
  std::vector<std::unique_ptr<report::RunData>> keep;
  for (const auto& [scene, v] : groups) {
    std::vector<report::LabeledRun> labeled;
    std::vector<std::string> seen;
    for (const auto& r : runs) {
      if (r.scene != scene || r.views != v) continue;
      if (std::find(seen.begin(), seen.end(), r.label) != seen.end()) continue;
      const fs::path dir = out_dir / r.dir;
      if (!fs::is_regular_file(dir / "results.json")) continue;
      try {
        keep.push_back(std::make_unique<report::RunData>(report::load_run(dir)));
      } catch (const Error& e) {
        continue;
      }
      seen.push_back(r.label);
      labeled.push_back({fmt::format("{} (seed {})", r.label, r.seed), keep.back().get()});
    }
    const std::string title =
        fmt::format("<h3>{}, {} views</h3>\n", html_escape(scene), v == 0 ? std::string("all") : std::to_string(v));
    if (labeled.empty()) {
      curves += title + "<p class=\"note\">No finished run yet.</p>\n";
      continue;
    }
    curves += title + report::curves_html(labeled);
    views += title + report::views_html(labeled, report::ImageEncoding::Jpeg, config.report_max_views);
    layers += title + report::layers_html(labeled);
  }
  page.add_section("curves", "Training curves", curves);
  page.add_section("views", "Test views", views.empty() ? "<p class=\"note\">No finished run yet.</p>\n" : views);
  page.add_section("layers", "Gaussians per depth layer",
                   layers.empty() ? "<p class=\"note\">No finished run yet.</p>\n" : layers);

  std::vector<std::vector<std::string>> imr_rows;
  for (const auto& r : rows)
    imr_rows.push_back({r.scene, std::to_string(r.views), r.label, r.imr ? fmt::format("{:.4f}", *r.imr) : "—",
                        r.imr_note});
  page.add_section("imr", "IMR (inter-model robustness)",
                   fmt::format("<p class=\"note\">Over each method's seeds, with the release's settings ({} "
                               "depth-strata samples, Taylor–Bures cost, ε = 0.1, reached by ε-scaling); reference camera: image 0 of the "
                               "scene. Lower = more stable; the paper reports 3.0–3.3 on LLFF (docs/imr.md explains "
                               "what the released setting can and cannot tell apart).</p>\n",
                               config.imr_samples) +
                       report::html_table({"scene", "views", "method", "IMR", "note"}, imr_rows, 3));
  return page.str();
}

}  // namespace d2gs::experiment
