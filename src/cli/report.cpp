// d2gs report: a self-contained HTML page of a training run (metrics, training curves, test views with
// error maps, Gaussians per depth layer). Experiments get theirs from `d2gs experiment`.
#include <filesystem>
#include <memory>
#include <string>

#include "cli/commands.hpp"
#include "d2gs/report/run_report.hpp"

namespace d2gs::cli {

Run add_report_command(CLI::App& app) {
  auto* cmd = app.add_subcommand("report", "Write a self-contained HTML report of a training run");
  cmd->footer("One file, no outside resources: images embedded, charts as inline SVG.\n"
              "Example: d2gs report -m out/fern_d2gs   (writes out/fern_d2gs/report.html)");
  auto model_dir = std::make_shared<std::string>();
  auto output = std::make_shared<std::string>();
  add_option(*cmd, "-m,--model-path", *model_dir, "Run folder written by d2gs train")->required();
  add_option(*cmd, "-o,--output", *output, "HTML file to write (default: MODEL/report.html)");
  return [model_dir, output]() -> int {
    const auto path = report::write_run_report(*model_dir, *output);
    std::printf("written %s\n", path.c_str());
    return 0;
  };
}

}  // namespace d2gs::cli
