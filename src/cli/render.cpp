#include "cli/commands.hpp"
#include "d2gs/core/error.hpp"

namespace d2gs::cli {

Run add_render_command(CLI::App& app) {
  app.add_subcommand("render", "(not implemented yet)");
  return [] () -> int { fail("'render' is not implemented yet"); };
}

}  // namespace d2gs::cli
