// d2gs train: sparse-view 3DGS / DropGaussian / D²GS training.
#include <deque>
#include <regex>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include "cli/commands.hpp"
#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/json_value.hpp"
#include "d2gs/report/run_report.hpp"
#include "d2gs/train/options.hpp"
#include "d2gs/train/presets.hpp"
#include "d2gs/train/trainer.hpp"

namespace d2gs::cli {
namespace {

// A range error of validate() on a value that the --config file gave and the command line did not: the file
// and its key named ("FILE: key 'iterations' must be > 0 (got -5)"), not a flag that was never typed. Other
// errors are rethrown as they are.
[[noreturn]] void fail_naming_the_file(const std::string& file, const nlohmann::json& from_file,
                                       const nlohmann::json& given, const Error& e) {
  const std::string what = e.what();
  const auto from_the_file = [&](const std::string& key) { return from_file.contains(key) && !given.contains(key); };
  std::smatch m;
  static const std::regex flag(R"(^option (--[a-z0-9-]+)(.*)$)");
  if (std::regex_match(what, m, flag))
    for (const TrainOption& o : train_options())
      if (o.flag() == m[1].str() && from_the_file(o.name)) fail_file(file, "key '{}'{}", o.name, m[2].str());
  static const std::regex schedule(R"(^(save|checkpoint|test) iteration (.*)$)");
  if (std::regex_match(what, m, schedule)) {
    const std::string list = m[1].str() + "_iterations";
    if (from_the_file(list) || from_the_file("iterations"))
      fail_file(file, "key '{}': iteration {} (key 'iterations' or --iterations)", list, m[2].str());
  }
  throw e;
}

}  // namespace

Run add_train_command(CLI::App& app) {
  auto* cmd = app.add_subcommand("train", "Train a Gaussian model from the training views of a scene");
  cmd->footer(
      "Outputs (the original 3DGS layout): MODEL/config.json, cameras.json, input.ply,\n"
      "point_cloud/iteration_N/point_cloud.ply, train_log.jsonl, chkpntN.bin, test/ours_N/{renders,gt},\n"
      "results.json. Defaults are the hyper-parameters of method.md §2. One `d2gs train` at a time per\n"
      "MODEL folder (a lock); a run stopped before its first checkpoint starts again with the same command.\n"
      "Example: d2gs train -s ../shared/data/nerf_llff_data/fern -m out/fern_3dgs -r 8 --n-views 3 --method 3dgs");
  auto config_file = std::make_shared<std::string>();
  auto resume = std::make_shared<std::string>();
  add_option(*cmd, "--config", *config_file, "JSON file of options (keys as in a saved config.json); flags override it")
      ->group("Run");
  add_option(*cmd, "--resume", *resume,
             "Continue from a checkpoint (chkpntN.bin) bit-identically: the same scene, -r, split and training "
             "options, --iterations at least the checkpoint's (anything else is refused: docs/formats.md)")
      ->group("Run");
  // Every training option from its one declaration (train/options.hpp): flag, former names, help, range
  // and default. What the command line gives becomes config.json keys over the --config file.
  struct Bound {
    const TrainOption* option;
    CLI::Option* cli = nullptr;
    std::string word = {};
    std::vector<std::string> words = {};
    bool on = false;
  };
  auto bound = std::make_shared<std::deque<Bound>>();  // a deque: CLI11 keeps the members' addresses
  for (const TrainOption& o : train_options()) {
    Bound& b = bound->emplace_back(Bound{&o});
    std::string names = o.short_flag.empty() ? o.flag() : o.short_flag + "," + o.flag();
    for (const auto& alias : o.aliases) names += "," + flag_of(alias);
    const std::string description =
        fmt::format("{} ({}default {})", o.help, o.range.empty() ? "" : o.range + "; ", o.default_text());
    if (o.kind == OptionKind::Flag) {
      b.cli = cmd->add_flag(names + ",!--no-" + o.flag().substr(2), b.on, description);
    } else if (o.kind == OptionKind::IntegerList || o.kind == OptionKind::NameList) {
      b.cli = cmd->add_option(names, b.words, description)->delimiter(',')->type_name(o.type_name);
    } else {
      b.cli = cmd->add_option(names, b.word, description)->type_name(o.type_name);
    }
    b.cli->group(o.group);
  }

  return [config_file, resume, bound]() -> int {
    nlohmann::json given = nlohmann::json::object();
    for (const Bound& b : *bound) {
      if (b.cli->count() == 0) continue;
      const TrainOption& o = *b.option;
      given[o.name] = o.parse(o.kind == OptionKind::Flag          ? std::vector<std::string>{b.on ? "true" : "false"}
                              : o.kind == OptionKind::IntegerList || o.kind == OptionKind::NameList ? b.words
                                                                  : std::vector<std::string>{b.word});
    }
    TrainConfig c;
    nlohmann::json from_file = nlohmann::json::object();
    if (!config_file->empty()) {
      const nlohmann::json j = read_json_file(*config_file);
      try {
        update_from_json(c, j, RecordedKeys::Ignore);  // the split, scene extent, ... are saved for the record
      } catch (const Error& e) {
        fail_file(*config_file, "{}", e.what());
      }
      from_file = with_current_names(j);
    }
    // Presets apply over the file; explicit flags apply over both.
    apply_given_options(c, given);
    if (!config_file->empty()) {
      try {
        c.validate();
      } catch (const Error& e) {
        fail_naming_the_file(*config_file, from_file, given, e);
      }
    }
    // config.json records the scene absolute, so that eval and imr find it from any working folder.
    if (!c.source.empty()) c.source = std::filesystem::absolute(c.source).lexically_normal().string();
    Trainer trainer(c, *resume);
    trainer.run();
    if (std::filesystem::is_regular_file(std::filesystem::path(c.model_dir) / "results.json"))
      report::write_run_report_or_warn(c.model_dir);
    return 0;
  };
}

}  // namespace d2gs::cli
