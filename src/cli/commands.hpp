#pragma once
// One file per subcommand; each registers itself on the top-level CLI11 app and returns the callback
// that runs it. Callbacks throw d2gs::Error on bad input; main() turns that into one line and exit 1.
#include <functional>
#include <string>

#include <CLI/CLI.hpp>

#include "cli/option_checks.hpp"

namespace d2gs::cli {

using Run = std::function<int()>;

Run add_info_command(CLI::App& app);
Run add_demo_command(CLI::App& app);
Run add_render_command(CLI::App& app);
Run add_train_command(CLI::App& app);
Run add_eval_command(CLI::App& app);
Run add_imr_command(CLI::App& app);
Run add_init_command(CLI::App& app);
Run add_report_command(CLI::App& app);
Run add_experiment_command(CLI::App& app);

}  // namespace d2gs::cli
