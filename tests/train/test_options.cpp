// The declaration of every training option (train/options.hpp): one name that is both the config.json
// key and the flag, former names still taken, each option's range checked under the flag that exists,
// and `d2gs train --help` listing every option once with its range and default.
#include <gtest/gtest.h>

#include <set>
#include <string>
#include <tuple>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/train/config.hpp"
#include "d2gs/train/options.hpp"
#include "test_errors.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {

TEST(TrainOptions, OneNameForKeyAndFlagAndEveryKeyDeclared) {
  std::set<std::string> names;
  for (const TrainOption& o : train_options()) {
    EXPECT_TRUE(names.insert(o.name).second) << o.name << " declared twice";
    for (const auto& alias : o.aliases) EXPECT_TRUE(names.insert(alias).second) << alias << " names two options";
    std::string dashed = o.name;
    for (char& ch : dashed)
      if (ch == '_') ch = '-';
    EXPECT_EQ(o.flag(), "--" + dashed);
    EXPECT_FALSE(o.help.empty()) << o.name;
    EXPECT_FALSE(o.default_text().empty()) << o.name;
    EXPECT_EQ(find_train_option(o.name), &o);
    for (const auto& alias : o.aliases) EXPECT_EQ(find_train_option(alias), &o);
  }
  // config.json holds exactly the declared options.
  nlohmann::json j;
  to_json(j, TrainConfig{});
  EXPECT_EQ(j.size(), train_options().size());
  for (const TrainOption& o : train_options()) EXPECT_TRUE(j.contains(o.name)) << o.name;
}

// The defaults are within every declared range (validate() needs only the required paths).
TEST(TrainOptions, DefaultsAreInRange) {
  const TrainConfig d;
  for (const TrainOption& o : train_options()) EXPECT_EQ(test::error_of([&] { o.check(d); }), "") << o.name;
}

// Former names: the config.json of a run trained before the names agreed, and an experiment's options.
TEST(TrainOptions, FormerNamesAreTakenAndWrittenUnderTheNewOnes) {
  TrainConfig c;
  update_from_json(c, nlohmann::json{{"model_dir", "run"}, {"dafe_prior_dir", "stereo"}, {"drop_rate", 0.3}});
  EXPECT_EQ(c.model_dir, "run");
  EXPECT_EQ(c.dafe.prior, "stereo");
  EXPECT_DOUBLE_EQ(c.dropgaussian_max_rate, 0.3);
  nlohmann::json j;
  to_json(j, c);
  EXPECT_EQ(j["model_path"], "run");
  EXPECT_EQ(j["dafe_prior"], "stereo");
  EXPECT_FALSE(j.contains("model_dir"));
  EXPECT_FALSE(j.contains("dafe_prior_dir"));
  // A name and a former name of one option: refused, and nothing taken.
  TrainConfig d;
  const std::string twice = test::error_of([&] { update_from_json(d, nlohmann::json{{"dafe_prior", "a"}, {"dafe_prior_dir", "b"}, {"iterations", 5}}); });
  EXPECT_NE(twice.find("a second time"), std::string::npos) << twice;
  EXPECT_EQ(d.iterations, TrainConfig{}.iterations);
  EXPECT_EQ(with_current_names(nlohmann::json{{"dafe_prior_dir", "x"}, {"seed", 1}, {"gone", 2}}),
            (nlohmann::json{{"dafe_prior", "x"}, {"seed", 1}, {"gone", 2}}));
}

// A config.json written by d2gs 5e0b5a1 (before the names agreed; fern, D²GS, its saved split and
// extent) is read as it was: every value taken under the option's current name.
TEST(TrainOptions, ConfigJsonOfAnOlderRunIsRead) {
  const nlohmann::json old = nlohmann::json::parse(read_file(test::source_dir() / "tests/train/fixtures/config_5e0b5a1_d2gs.json"));
  ASSERT_TRUE(old.contains("dafe_prior_dir"));
  ASSERT_TRUE(old.contains("model_dir"));
  TrainConfig c;
  update_from_json(c, old, RecordedKeys::Ignore);
  nlohmann::json now;
  to_json(now, c);
  nlohmann::json expected = with_current_names(old);
  for (const char* recorded : kRecordedKeys) expected.erase(recorded);
  // Options added since (init_dense_method) take their defaults.
  for (const TrainOption& o : train_options())
    if (!expected.contains(o.name)) expected[o.name] = o.get(TrainConfig{});
  EXPECT_EQ(now, expected);
  EXPECT_NE(test::error_of([&] { update_from_json(c, old); }).find("unknown key"), std::string::npos)
      << "the recorded keys are options only when asked to ignore them";
}

// validate() used to name --sh-increase-every, --min-opacity, --density-refresh-every and --log-every,
// which did not exist: now each is a flag, and its range error names it.
TEST(TrainCli, RangeErrorsNameFlagsThatExist) {
  const auto dir = test::scratch_dir();
  const std::string fern = (test::shared_data() / "nerf_llff_data/fern").string();
  for (const auto& [args, expected] : std::vector<std::pair<std::string, std::string>>{
           {"--sh-increase-every 0", "option --sh-increase-every must be > 0 (got 0)"},
           {"--min-opacity 1", "option --min-opacity must be in [0, 1) (got 1)"},
           {"--density-refresh-every -5", "option --density-refresh-every must be > 0 (got -5)"},
           {"--log-every 0", "option --log-every must be > 0 (got 0)"},
           {"--dropgaussian-max-rate 1.5", "option --dropgaussian-max-rate must be in [0, 1) (got 1.5)"},
           {"--drop-rate 1.5", "option --dropgaussian-max-rate must be in [0, 1) (got 1.5)"},
           {"-r 3", "option --resolution must be 1, 2, 4 or 8 (got 3)"},
           {"--iterations many", "option --iterations: 'many' is not an integer"},
           {"--dafe-mask-rule halfway", "option --dafe-mask-rule: 'halfway' is not one of percentile, threshold"},
           {"--dafe-mask-rule threshold --dafe-tau 5", "option --dafe-tau must be a fraction in [0, 1] for the threshold rule (got 5)"},
           {"--regularisers opacity-noise,dropout", "option --regularisers: 'dropout' is not one of opacity-noise, opacity-decay"},
           {"--regularisers opacity-decay,opacity-decay", "option --regularisers: 'opacity-decay' is named twice"},
           {"--opacity-noise-sigma 1", "option --opacity-noise-sigma must be in [0, 1) (got 1)"},
           {"--opacity-decay-factor 0", "option --opacity-decay-factor must be in (0, 1] (got 0)"},
           {"--init-color-filter 1.5", "option --init-color-filter must be in [0, 1] (got 1.5)"},
           {"--init-pm-distinctiveness 3", "option --init-pm-distinctiveness must be in [0, 2] (got 3)"},
           {"--init-pm-uniqueness -0.5", "option --init-pm-uniqueness must be in [0, 2] (got -0.5)"},
           {"--random-points 2000000000", "option --random-points must be in [1, 10000000] (got 2000000000)"},
           {"--opacity-lr nan", "option --opacity-lr: 'nan' is not a finite number"},
           {"--opacity-lr -inf", "option --opacity-lr: '-inf' is not a finite number"}}) {
    const auto r = test::run_cli(fmt::format("train -s '{}' -m '{}' {}", fern, (dir / "run").string(), args));
    EXPECT_EQ(r.exit_code, 1) << args << "\n" << r.output;
    EXPECT_NE(r.output.find("d2gs: error: " + expected), std::string::npos) << args << "\n" << r.output;
    EXPECT_FALSE(std::filesystem::exists(dir / "run")) << args;
  }
  // A flag's --no- form.
  const auto no = test::run_cli(fmt::format("train -s '{}' -m '{}' --no-dafe --no-dd-use-layers --method d2gs "
                                            "--dafe-lambda -1", fern, (dir / "run").string()));
  EXPECT_NE(no.output.find("option --dafe-lambda must be ≥ 0 (got -1)"), std::string::npos) << no.output;
}

// A bad value of a --config file is said with the file and its key, not under a flag that was not typed
// ("option --iterations must be > 0"); a flag that was typed is still named as a flag.
TEST(TrainCli, RangeErrorsOfAConfigFileNameTheFileAndTheKey) {
  const auto dir = test::scratch_dir();
  const std::string fern = (test::shared_data() / "nerf_llff_data/fern").string();
  const auto file = dir / "config.json";
  for (const auto& [config, flags, expected] : std::vector<std::tuple<nlohmann::json, std::string, std::string>>{
           {{{"iterations", -5}}, "", file.string() + ": key 'iterations' must be > 0 (got -5)"},
           {{{"iterations", nullptr}}, "", file.string() + ": key 'iterations' must be an integer, got null"},
           {{{"iterations", 20}, {"save_iterations", {100}}},
            "",
            file.string() +
                ": key 'save_iterations': iteration 100 is outside 1..20 (key 'iterations' or --iterations)"},
           {{{"iterations", 20}}, "--iterations -5", "option --iterations must be > 0 (got -5)"}}) {
    write_file_atomic(file, config.dump());
    const auto r = test::run_cli(
        fmt::format("train -s '{}' -m '{}' --config '{}' {}", fern, (dir / "run").string(), file.string(), flags));
    EXPECT_EQ(r.exit_code, 1) << config.dump() << "\n" << r.output;
    EXPECT_EQ(r.output, "d2gs: error: " + expected + "\n") << config.dump();
    EXPECT_FALSE(std::filesystem::exists(dir / "run")) << config.dump();
  }
}

// --dafe-prior naming no folder: said so, not as the first view's missing map ("dp/nothere/image001.npy: DAFE
// prior missing").
TEST(TrainCli, DafePriorFolderThatDoesNotExistIsSaidSo) {
  const auto dir = test::scratch_dir();
  const std::string fern = (test::shared_data() / "nerf_llff_data/fern").string();
  const auto prior =
      test::run_cli(fmt::format("-q train -s '{}' -m '{}' -r 8 --n-views 3 --init random --iterations 1 "
                                "--device cpu --method d2gs --dafe-prior '{}'",
                                fern, (dir / "run").string(), (dir / "nothere").string()));
  EXPECT_EQ(prior.exit_code, 1) << prior.output;
  EXPECT_NE(prior.output.find("d2gs: error: " + (dir / "nothere").string() + ": --dafe-prior: no such folder\n"),
            std::string::npos)
      << prior.output;
}

// --regularisers: a list of names on the command line and in config.json; "none" is the empty list.
TEST(TrainOptions, RegularisersAreAListOfNames) {
  const TrainOption* o = find_train_option("regularisers");
  ASSERT_NE(o, nullptr);
  EXPECT_EQ(o->parse({"opacity-decay", "opacity-noise"}), nlohmann::json({"opacity-decay", "opacity-noise"}));
  EXPECT_EQ(o->parse({"none"}), nlohmann::json::array());
  EXPECT_EQ(find_train_option("opacity_reset_at")->parse({"none"}), nlohmann::json::array());  // Binocular3DGS's
  TrainConfig c;
  update_from_json(c, nlohmann::json{{"regularisers", {"opacity-noise"}}, {"opacity_noise_sigma", 0.4}});
  EXPECT_EQ(c.regularisers, std::vector<std::string>{"opacity-noise"});
  EXPECT_DOUBLE_EQ(c.opacity_noise_sigma, 0.4);
  nlohmann::json j;
  to_json(j, c);
  EXPECT_EQ(j["regularisers"], nlohmann::json({"opacity-noise"}));
  EXPECT_EQ(test::error_of([&] { update_from_json(c, nlohmann::json{{"regularisers", "opacity-noise"}}); }),
            "key 'regularisers' has the wrong type (expected list of names, got string)");
  EXPECT_EQ(test::error_of([&] { update_from_json(c, nlohmann::json{{"regularisers", {"noise"}}}); }),
            "key 'regularisers': 'noise' is not one of opacity-noise, opacity-decay, stereo-depth, anisotropy, scale-l1");
}

// `d2gs train --help`: every option once, with its range and its default.
TEST(TrainCli, HelpListsEveryOptionOnceWithItsRange) {
  const auto r = test::run_cli("train --help");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const TrainOption& o : train_options()) {
    // The flag starts an entry ("  --flag" or "  -s,--flag") and appears nowhere else as an entry.
    const std::string entry = (o.short_flag.empty() ? "  " : "  " + o.short_flag + ",") + o.flag();
    EXPECT_EQ(test::count_occurrences(r.output, entry + " ") + test::count_occurrences(r.output, entry + ","), 1u)
        << o.flag() << "\n" << r.output;
    const auto at = r.output.find(entry);
    ASSERT_NE(at, std::string::npos) << o.flag();
    const std::string rest = r.output.substr(at, r.output.find("\n  -", at + 1) - at);
    if (!o.range.empty()) {
      EXPECT_NE(rest.find(o.range), std::string::npos) << o.flag() << ": " << rest;
    }
    EXPECT_NE(rest.find("default " + o.default_text()), std::string::npos) << o.flag() << ": " << rest;
  }
}

// A word that names no command: said so, with the commands there are (CLI11 said "A subcommand is required").
TEST(Cli, UnknownCommandIsNamed) {
  const auto r = test::run_cli("trian -s x");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("d2gs: error: unknown command 'trian' (commands: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("train"), std::string::npos) << r.output;
  EXPECT_EQ(test::run_cli("-q --version").exit_code, 0);
}

// What CLI11 cannot parse, and the option checks of the other commands (cli/option_checks.hpp): one line
// "d2gs: error: COMMAND: ..." in train's words, exit 1 (CLI11 printed two lines, without the prefix, with its own
// exit codes 104-114, and "Value 0 not in range 0.000000 to 1797693134862315708...").
TEST(Cli, ParseErrorsAreOneLineInTrainsWords) {
  const auto dir = test::scratch_dir();
  const std::string fern = (test::shared_data() / "nerf_llff_data/fern").string();
  const std::string run = (dir / "run").string();
  const std::string big = "18446744073709551616";  // 2^64: CLI11 clamped it to 2^64 - 1
  for (const auto& [args, expected] : std::vector<std::pair<std::string, std::string>>{
           {"eval -m '" + run + "' --iteration 0", "eval: option --iteration must be ≥ 1 (got 0)"},
           {"eval -m '" + run + "' --iteration ''", "eval: option --iteration: '' is not an integer"},
           {"info -s '" + fern + "' -r nan", "info: option --resolution: 'nan' is not an integer"},
           {"info -s '" + fern + "' -r 8 --train-views ''", "info: option --train-views: '' is not an integer"},
           {"info -s '" + fern + "' -r 8 --n-views 0x3", "info: option --n-views: '0x3' is not an integer"},
           {"info -s '" + fern + "' -r 8 -r 8", "info: --resolution given twice"},
           {"train -s '" + fern + "' -m '" + run + "' -r 8 -r 8", "train: --resolution given twice"},
           {"train -s '" + fern + "' -m '" + run + "' --n-views 3 --n-views 3 --n-views 3",
            "train: --n-views given 3 times"},
           {"train -s '" + fern + "' -m '" + run + "' --resume ''", "train: option --resume: must not be empty"},
           {"train -s '" + fern + "' -m '" + run + "' --config ''", "train: option --config: must not be empty"},
           {"report -m '" + run + "' -o ''", "report: option --output: must not be empty"},
           {"demo -o '" + run + "' --scene-only --seed " + big,
            "demo: option --seed: '" + big + "' is not a whole number ≥ 0"},
           {"demo -o '" + run + "' --scene-only --seed -1", "demo: option --seed: '-1' is not a whole number ≥ 0"},
           {"demo -o '" + run + "' --scene-only --views 1", "demo: option --views must be in [2, 1000] (got 1)"},
           {"init -s '" + fern + "' -r 8 --n-views 3 --no-dense -o '" + run + "' --seed " + big,
            "init: option --seed: '" + big + "' is not a whole number ≥ 0"},
           {"init -s '" + fern + "' -r 8 --n-views 3 --no-dense -o '" + run + "' --min-angle x",
            "init: option --min-angle: 'x' is not a number"},
           {"render -m '" + fern + "/poses_bounds.npy' -s '" + fern + "' -o '" + run + "' --sh-degree 4",
            "render: option --sh-degree must be in [-1, 3] (got 4)"},
           {"experiment -o '" + run + "' --run-index -2", "experiment: option --run-index must be ≥ 0 (got -2)"},
           {"experiment -o '" + run + "' --jobs 0", "experiment: option --jobs must be in [1, 256] (got 0)"},
           {"info -s", "info: --source needs a value"}}) {
    const auto r = test::run_cli(args);
    EXPECT_EQ(r.exit_code, 1) << args << "\n" << r.output;
    EXPECT_EQ(r.output, "d2gs: error: " + expected + "\n") << args;
    EXPECT_FALSE(std::filesystem::exists(dir / "run")) << args;
  }
  // Valid values pass the checks: these end at the command's own error (no run folder), not at the option.
  for (const std::string& args : {"eval -m '" + run + "' --iteration 1", "report -m '" + run + "' -o x.html"}) {
    const auto r = test::run_cli(args);
    EXPECT_EQ(r.exit_code, 1) << args << "\n" << r.output;
    EXPECT_EQ(r.output.find("option"), std::string::npos) << args << "\n" << r.output;
    EXPECT_NE(r.output.find(run), std::string::npos) << args << "\n" << r.output;
  }
  const auto valid = test::run_cli("-q info -s '" + fern + "' -r 8 --train-views 1,10,19 --json");
  EXPECT_EQ(valid.exit_code, 0) << valid.output;
  // --help is still help, exit 0.
  for (const char* args : {"eval --help", "imr --help", "demo --help", "--help"}) {
    const auto help = test::run_cli(args);
    EXPECT_EQ(help.exit_code, 0) << args << "\n" << help.output;
    EXPECT_NE(help.output.find("Usage:"), std::string::npos) << args << "\n" << help.output;
  }
}

}  // namespace
}  // namespace d2gs
