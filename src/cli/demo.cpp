#include "cli/commands.hpp"
#include "d2gs/core/error.hpp"

namespace d2gs::cli {

Run add_demo_command(CLI::App& app) {
  app.add_subcommand("demo", "(not implemented yet)");
  return [] () -> int { fail("'demo' is not implemented yet"); };
}

}  // namespace d2gs::cli
