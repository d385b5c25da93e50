#include "d2gs/report/run_report.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>

#include <fmt/format.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/log.hpp"
#include "d2gs/report/svg_chart.hpp"

namespace d2gs::report {
namespace fs = std::filesystem;

namespace {

std::string number(double v, int decimals) {
  return std::isfinite(v) ? fmt::format("{:.{}f}", v, decimals) : std::string("—");
}

int decimals_of(const std::string& metric) { return metric == "PSNR" ? 2 : 4; }

std::string metrics_html(const RunData& run) {
  if (!run.results.is_object())
    return "<p class=\"note\">No results.json: the run has not finished (or was not evaluated). Run "
           "<code>d2gs eval -m RUN</code> to score its last saved model.</p>\n";
  const Metrics mean = mean_metrics(run.results);
  const auto per_view = view_metrics(run.results);
  std::vector<std::string> present;
  for (const auto& [k, v] : mean) present.push_back(k);
  const auto order = metric_order(present);
  std::vector<std::string> header = {"view"};
  for (const auto& m : order) header.push_back(m + (lower_is_better(m) ? " ↓" : " ↑"));
  std::vector<std::vector<std::string>> rows;
  for (const auto& [name, metrics] : per_view) {
    std::vector<std::string> row = {name};
    for (const auto& m : order) row.push_back(metrics.count(m) ? number(metrics.at(m), decimals_of(m)) : "—");
    rows.push_back(row);
  }
  std::vector<std::string> row = {"mean"};
  for (const auto& m : order) row.push_back(number(mean.at(m), decimals_of(m)));
  rows.push_back(row);
  std::string out = html_table(header, rows);
  std::vector<std::string> missing;
  for (const char* m : {"LPIPS", "AVGE"})
    if (!mean.count(m)) missing.emplace_back(m);
  if (!missing.empty()) {
    // d2gs eval records why LPIPS was skipped (e.g. no weights file); d2gs train does not compute it.
    std::string why = " (<code>d2gs eval -m RUN --lpips-weights FILE</code> adds them)";
    const auto& l = run.results.contains("lpips") ? run.results["lpips"] : nlohmann::json();
    if (l.is_object() && l.contains("reason") && l["reason"].is_string())
      why = ": " + html_escape(l["reason"].get<std::string>());
    out += fmt::format("<p class=\"note\">Unavailable in results.json: {}{}.</p>\n",
                       html_escape(fmt::format("{}", fmt::join(missing, ", "))), why);
  }
  return out;
}

std::string summary_html(const RunData& run) {
  const auto& c = run.config;
  const auto get = [&](const char* key) -> std::string {
    if (!c.is_object() || !c.contains(key)) return "—";
    const auto& v = c[key];
    return v.is_string() ? v.get<std::string>() : v.dump();
  };
  const auto split = [&](const char* key) -> std::string {
    if (!c.is_object() || !c.contains("split") || !c["split"].is_object() || !c["split"].contains(key)) return "—";
    return c["split"][key].dump();
  };
  const bool oracle = c.is_object() && c.contains("init_is_oracle") && c["init_is_oracle"].is_boolean() &&
                      c["init_is_oracle"].get<bool>();
  std::vector<std::vector<std::string>> rows = {
      {"method", run.method()},
      {"scene", get("source")},
      {"resolution", "1/" + get("resolution")},
      {"training views", split("train")},
      {"test views", split("test")},
      {"iterations", get("iterations")},
      {"seed", get("seed")},
      {"preset", [&] {
         const std::string preset = get("preset") == "—" ? "" : get("preset");
         const std::string scene = get("scene_preset") == "—" ? "" : get("scene_preset");
         if (preset.empty() && scene.empty()) return std::string("none (the method's defaults and flags)");
         return preset.empty() ? "scene " + scene : scene.empty() ? preset : preset + " / scene " + scene;
       }()},
      {"initial points", get("init") + (oracle ? " (ORACLE: saw the test views)" : "")},
      {"final model", run.iteration >= 0 ? fmt::format("iteration {}", run.iteration) : std::string("none saved")},
  };
  if (run.results.is_object()) {
    if (run.results.contains("gaussians")) rows.push_back({"Gaussians", run.results["gaussians"].dump()});
    if (run.results.contains("train_seconds") && run.results["train_seconds"].is_number())
      rows.push_back({"training time", fmt::format("{:.1f} s", run.results["train_seconds"].get<double>())});
  }
  return html_table({"item", "value"}, rows, 99);
}

Image load_or_empty(const fs::path& p) { return p.empty() ? Image{} : read_image(p); }

}  // namespace

std::string curves_html(const std::vector<LabeledRun>& runs) {
  LineChart loss{"Training loss", "iteration", "loss", {}, true};
  LineChart psnr{"Test PSNR", "iteration", "PSNR (dB)", {}, false};
  LineChart count{"Number of Gaussians", "iteration", "Gaussians", {}, false};
  bool any_test = false;
  for (const auto& r : runs) {
    const TrainLog& log = r.run->log;
    loss.series.push_back({r.label, log.iteration, log.loss, false});
    count.series.push_back({r.label, log.iteration, log.gaussians, false});
    Series s{r.label, log.test_iteration, log.test_psnr, true};
    // The final evaluation is a test point too.
    if (r.run->results.is_object()) {
      const Metrics m = mean_metrics(r.run->results);
      if (m.count("PSNR") && r.run->iteration >= 0 &&
          (s.x.empty() || s.x.back() < static_cast<double>(r.run->iteration))) {
        s.x.push_back(r.run->iteration);
        s.y.push_back(m.at("PSNR"));
      }
    }
    any_test = any_test || !s.x.empty();
    psnr.series.push_back(s);
  }
  std::string out = "<div class=\"charts\">\n" + svg_line_chart(loss) + svg_line_chart(psnr) + svg_line_chart(count) +
                    "</div>\n";
  if (!any_test)
    out += "<p class=\"note\">No test PSNR logged (train with <code>--test-iterations</code> for a curve).</p>\n";
  return out;
}

std::string views_html(const std::vector<LabeledRun>& runs, ImageEncoding encoding, int max_views) {
  const RunData* first = nullptr;
  for (const auto& r : runs)
    if (!r.run->views.empty()) {
      first = r.run;
      break;
    }
  if (!first) return "<p class=\"note\">No test renders (test/ours_N/renders/) in this run.</p>\n";
  std::string out = "<p class=\"note\">Error maps: per-pixel mean absolute error over RGB, 0 (black) to ≥ 0.25 "
                    "(pale yellow).</p>\n";
  int shown = 0;
  for (const auto& view : first->views) {
    if (max_views >= 0 && shown >= max_views) break;
    ++shown;
    // A grid: ground truth then each run's render on the first row, each error map under its render.
    out += "<h3>" + html_escape(view.name) + "</h3>\n";
    out += fmt::format("<div class=\"views\" style=\"grid-template-columns:repeat({},minmax(0,1fr))\">\n",
                       runs.size() + 1);
    const Image gt = load_or_empty(view.gt);
    out += gt.empty() ? std::string("<figure><figcaption>no ground truth</figcaption></figure>\n")
                      : "<figure>" + img_tag(gt, "ground truth " + view.name, encoding) +
                            "<figcaption>ground truth</figcaption></figure>\n";
    std::string errors = "<figure></figure>\n";
    for (const auto& r : runs) {
      const TestView* match = nullptr;
      for (const auto& v : r.run->views)
        if (v.name == view.name) match = &v;
      if (!match) {
        out += "<figure><figcaption>" + html_escape(r.label) + ": no render</figcaption></figure>\n";
        errors += "<figure></figure>\n";
        continue;
      }
      const Image render = read_image(match->render);
      std::string caption = r.label;
      const auto per_view = view_metrics(r.run->results);
      // results.json names views by file name (image000.png), renders by stem (image000).
      for (const auto& [name, metrics] : per_view)
        if ((name == view.name || fs::path(name).stem().string() == view.name) && metrics.count("PSNR")) {
          caption += fmt::format(" · {:.2f} dB", metrics.at("PSNR"));
          break;
        }
      out += "<figure>" + img_tag(render, r.label + " render " + view.name, encoding) + "<figcaption>" +
             html_escape(caption) + "</figcaption></figure>\n";
      if (!gt.empty() && gt.width == render.width && gt.height == render.height)
        errors += "<figure>" + img_tag(error_map(render, gt), r.label + " error " + view.name, encoding) +
                  "<figcaption>" + html_escape(r.label + " error") + "</figcaption></figure>\n";
      else
        errors += "<figure><figcaption>no error map (no matching ground truth)</figcaption></figure>\n";
    }
    out += errors + "</div>\n";
  }
  if (max_views >= 0 && static_cast<int>(first->views.size()) > max_views)
    out += fmt::format("<p class=\"note\">{} of {} test views shown.</p>\n", max_views, first->views.size());
  return out;
}

std::string layers_html(const std::vector<LabeledRun>& runs) {
  std::vector<std::vector<std::string>> rows;
  BarChart chart{"Gaussians per depth layer", "Gaussians", {"near", "middle", "far"}, {}};
  std::string notes;
  for (const auto& r : runs) {
    if (!r.run->layers) {
      notes += fmt::format("<p class=\"note\">{}: no layer counts ({}).</p>\n", html_escape(r.label),
                           html_escape(r.run->layers_note));
      continue;
    }
    const LayerCounts& c = *r.run->layers;
    const double total = static_cast<double>(c.near + c.middle + c.far + c.behind);
    const auto pct = [&](std::size_t v) { return total > 0 ? fmt::format("{} ({:.0f} %)", v, 100.0 * v / total) : std::to_string(v); };
    rows.push_back({r.label, pct(c.near), pct(c.middle), pct(c.far), std::to_string(c.behind),
                    fmt::format("{:.3g} / {:.3g}", c.near_limit, c.far_limit)});
    chart.series.push_back({r.label, {}, {static_cast<double>(c.near), static_cast<double>(c.middle), static_cast<double>(c.far)}, false});
  }
  if (rows.empty()) return notes.empty() ? "<p class=\"note\">No layer counts.</p>\n" : notes;
  const LayerCounts* any = nullptr;
  for (const auto& r : runs)
    if (r.run->layers) any = &*r.run->layers;
  std::string out = fmt::format(
      "<p class=\"note\">Depth = view-space z of each Gaussian's mean w.r.t. the reference camera {}; layer limits: "
      "{}. The paper's observation: plain 3DGS piles Gaussians up near the camera and leaves the far field "
      "sparse.</p>\n",
      html_escape(any->camera), html_escape(any->boundary));
  out += html_table({"run", "near", "middle", "far", "behind camera", "limits (z)"}, rows);
  out += "<div class=\"charts\">\n" + svg_bar_chart(chart) + "</div>\n" + notes;
  return out;
}

std::string run_report_html(const RunData& run) {
  HtmlPage page("d2gs run report: " + run.dir.filename().string(), run.dir.string());
  const std::vector<LabeledRun> runs = {{run.method(), &run}};
  page.add_section("summary", "Run", summary_html(run));
  page.add_section("metrics", "Test metrics", metrics_html(run));
  page.add_section("curves", "Training curves", curves_html(runs));
  page.add_section("views", "Test views", views_html(runs, ImageEncoding::Jpeg));
  page.add_section("layers", "Gaussians per depth layer", layers_html(runs));
  page.add_section("imr", "IMR",
                   "<p class=\"note\">IMR compares independently trained models of one scene: see the experiment "
                   "report (<code>d2gs experiment</code>) or <code>d2gs imr RUN RUN ...</code>.</p>\n");
  return page.str();
}

fs::path write_run_report(const fs::path& run_dir, const fs::path& out) {
  const fs::path path = out.empty() ? run_dir / "report.html" : out;
  check_output_file(path);
  // Only an earlier report is replaced (html.cpp's pages name d2gs as their generator in the head): never
  // a run's config.json, its model or a user's file given as -o by mistake.
  std::error_code ec;
  if (fs::exists(path, ec)) {
    require_regular_file(path);  // a named pipe would block the read below
    std::string head(1024, '\0');
    std::ifstream in(path, std::ios::binary);
    in.read(head.data(), static_cast<std::streamsize>(head.size()));
    head.resize(static_cast<std::size_t>(std::max<std::streamsize>(in.gcount(), 0)));
    if (head.find("<meta name=\"generator\" content=\"d2gs\">") == std::string::npos)
      fail_file(path, "exists and is not a d2gs report: report replaces only its own pages (choose another -o)");
  }
  const RunData run = load_run(run_dir);
  write_file_atomic(path, run_report_html(run));
  return path;
}

void write_run_report_or_warn(const fs::path& run_dir) {
  try {
    const fs::path path = write_run_report(run_dir);
    spdlog::info("report: {}", path.string());
  } catch (const std::exception& e) {
    spdlog::warn("report: not written ({})", e.what());
  }
}

}  // namespace d2gs::report
