// d2gs: sparse-view 3D Gaussian Splatting (D²GS) from the command line.
#include <cstdio>
#include <exception>
#include <filesystem>
#include <map>
#include <regex>
#include <string>

#include "cli/commands.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/interrupt.hpp"
#include "d2gs/core/log.hpp"

namespace {

// What CLI11 says of a command line it cannot parse, in the words of d2gs's other errors (one line, the
// option named first): a failed check of cli/option_checks.hpp is "option --NAME: PROBLEM" or "option --NAME must
// be ..." as d2gs train says them, a repeated option "--NAME given twice", an option without its value "--NAME
// needs a value", a value CLI11 cannot convert "--NAME: 'WORD' is not a valid value"; other messages stay.
std::string parse_error_message(const CLI::ParseError& e) {
  const std::string what = e.what();
  std::smatch m;
  static const std::regex at_most(R"(^(\S+): At Most \d+ required but received (\d+)$)");
  static const std::regex missing(R"(^(\S+): \d+ required \S+ missing$)");
  static const std::regex conversion(R"(^Could not convert: (\S+) = (.*)$)");
  static const std::regex check(R"(^(-\S+): (.*)$)");
  if (dynamic_cast<const CLI::ValidationError*>(&e) && std::regex_match(what, m, check))
    return "option " + m[1].str() + (m[2].str().rfind("must be", 0) == 0 ? " " : ": ") + m[2].str();
  if (std::regex_match(what, m, at_most))
    return m[1].str() + " given " + (m[2].str() == "2" ? std::string("twice") : m[2].str() + " times");
  if (std::regex_match(what, m, missing)) return m[1].str() + " needs a value";
  if (std::regex_match(what, m, conversion)) return m[1].str() + ": '" + m[2].str() + "' is not a valid value";
  return what;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "d2gs: sparse-view 3D Gaussian Splatting with depth-and-density guided dropout (D2GS).\n"
      "Run `d2gs COMMAND --help` for the options of one command.",
      "d2gs"};
  app.require_subcommand(1);
  app.fallthrough();  // -q/-v may also follow the subcommand
  app.set_version_flag("--version", "d2gs 0.1.0");
  bool quiet = false, verbose = false;
  app.add_flag("-q,--quiet", quiet, "Only print errors (no progress lines)");
  app.add_flag("-v,--verbose", verbose, "Print debug messages");

  std::map<const CLI::App*, d2gs::cli::Run> runs;
  const auto add = [&](d2gs::cli::Run (*adder)(CLI::App&)) {
    const auto before = app.get_subcommands([](const CLI::App*) { return true; }).size();
    auto run = adder(app);
    const auto subs = app.get_subcommands([](const CLI::App*) { return true; });
    if (subs.size() > before) runs[subs.back()] = std::move(run);
  };
  add(d2gs::cli::add_info_command);
  add(d2gs::cli::add_render_command);
  add(d2gs::cli::add_init_command);
  add(d2gs::cli::add_train_command);
  add(d2gs::cli::add_eval_command);
  add(d2gs::cli::add_imr_command);
  add(d2gs::cli::add_demo_command);
  add(d2gs::cli::add_report_command);
  add(d2gs::cli::add_experiment_command);

  // The first word that is no option names the command: say which words would have been one.
  std::string command;
  for (int i = 1; i < argc; ++i) {
    const std::string word = argv[i];
    if (word.empty() || word[0] == '-') continue;
    std::string known;
    bool found = false;
    for (const auto& [sub, run] : runs) {
      known += (known.empty() ? "" : ", ") + sub->get_name();
      found = found || sub->get_name() == word;
    }
    if (!found) {
      std::fprintf(stderr, "d2gs: error: unknown command '%s' (commands: %s; d2gs --help)\n", word.c_str(), known.c_str());
      return 2;
    }
    command = word;
    break;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version: CLI11 prints them and exits 0. A bad command line: one line, exit 1 as for d2gs::Error.
    if (e.get_exit_code() == static_cast<int>(CLI::ExitCodes::Success)) return app.exit(e);
    std::fprintf(stderr, "d2gs: error: %s%s\n", command.empty() ? "" : (command + ": ").c_str(),
                 parse_error_message(e).c_str());
    return 1;
  }
  d2gs::set_verbosity(quiet ? d2gs::Verbosity::Quiet : verbose ? d2gs::Verbosity::Verbose : d2gs::Verbosity::Normal);
  try {
    const d2gs::InterruptScope interrupts;  // Ctrl-C stops at the commands' next check, cleaning up
    for (const auto& [sub, run] : runs)
      if (sub->parsed()) return run();
    return 2;
  } catch (const d2gs::Interrupted& e) {
    std::fprintf(stderr, "d2gs: %s\n", e.what());
    return 130;
  } catch (const d2gs::Error& e) {
    std::fprintf(stderr, "d2gs: error: %s\n", e.what());
    return 1;
  } catch (const std::filesystem::filesystem_error& e) {
    // A file system call that failed where no check foresaw it (a folder that cannot be created, a disk that
    // is full): the path and the reason, as the library's own errors name them.
    std::string what = e.what();
    if (const std::string prefix = "filesystem error: "; what.rfind(prefix, 0) == 0) what.erase(0, prefix.size());
    if (const auto bracket = what.find(" ["); bracket != std::string::npos) what.erase(bracket);
    if (e.path1().empty()) std::fprintf(stderr, "d2gs: error: %s\n", what.c_str());
    else std::fprintf(stderr, "d2gs: error: %s: %s\n", e.path1().c_str(), what.c_str());
    return 1;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "d2gs: error: out of memory\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "d2gs: error: internal: %s\n", e.what());
    return 3;
  }
}
