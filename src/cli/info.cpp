#include "cli/commands.hpp"
#include "d2gs/core/error.hpp"

namespace d2gs::cli {

Run add_info_command(CLI::App& app) {
  app.add_subcommand("info", "(not implemented yet)");
  return [] () -> int { fail("'info' is not implemented yet"); };
}

}  // namespace d2gs::cli
