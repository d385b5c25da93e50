#include "d2gs/experiment/slurm.hpp"

#include <algorithm>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"

namespace d2gs::experiment {
namespace fs = std::filesystem;

std::string shell_quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

namespace {

std::string job_name(const ExperimentConfig& config) {
  std::string n = "d2gs-" + config.name;
  for (char& c : n)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.')) c = '_';
  return n;
}

std::string common_header(const ExperimentConfig& config, const SlurmOptions& o, const std::string& suffix) {
  std::string s = "#!/bin/bash\n";
  s += fmt::format("#SBATCH --job-name={}{}\n", job_name(config), suffix);
  if (!o.partition.empty()) s += fmt::format("#SBATCH --partition={}\n", o.partition);
  if (!o.account.empty()) s += fmt::format("#SBATCH --account={}\n", o.account);
  return s;
}

void check(const SlurmOptions& o) {
  if (o.program.empty() || !o.program.is_absolute()) fail("slurm: the d2gs program path must be absolute");
  if (o.out_dir.empty() || !o.out_dir.is_absolute()) fail("slurm: the experiment folder must be absolute");
  if (o.cpus < 1) fail("slurm: --slurm-cpus must be ≥ 1");
  if (o.gpus < 0) fail("slurm: --slurm-gpus must be ≥ 0 (got {})", o.gpus);
  if (o.max_parallel < 0) fail("slurm: --slurm-max-parallel must be ≥ 0 (got {})", o.max_parallel);
  if (o.time.empty()) fail("slurm: --slurm-time must not be empty (e.g. 02:00:00)");
  for (const std::string* v : {&o.partition, &o.account, &o.time, &o.mem})
    if (v->find_first_of(" \t\n'\"\\$`") != std::string::npos) fail("slurm: option value '{}' has unsafe characters", *v);
  // The paths also stand unquoted in #SBATCH lines and comments: a line break there would end the line.
  for (const fs::path* p : {&o.program, &o.out_dir})
    if (std::any_of(p->native().begin(), p->native().end(), [](char c) { return static_cast<unsigned char>(c) < 0x20; }))
      fail("slurm: the path {} holds a line break or another control character", nlohmann::json(p->string()).dump());
}

}  // namespace

std::string slurm_array_script(const ExperimentConfig& config, std::size_t run_count, const SlurmOptions& o) {
  check(o);
  if (run_count == 0) fail("slurm: the experiment has no runs");
  std::string s = common_header(config, o, "");
  s += fmt::format("#SBATCH --array=0-{}{}\n", run_count - 1, o.max_parallel > 0 ? fmt::format("%{}", o.max_parallel) : "");
  s += fmt::format("#SBATCH --cpus-per-task={}\n", o.cpus);
  if (o.gpus > 0) s += fmt::format("#SBATCH --gres=gpu:{}\n", o.gpus);
  if (!o.mem.empty()) s += fmt::format("#SBATCH --mem={}\n", o.mem);
  s += fmt::format("#SBATCH --time={}\n", o.time);
  s += fmt::format("#SBATCH --output={}\n", (o.out_dir / "logs" / "slurm-%A_%a.out").string());
  s += fmt::format(
      "# {} runs of experiment '{}': array task i trains run i (DIR/experiment.json lists them) into the shared\n"
      "# folder below. Finished runs are skipped and an interrupted run resumes from its last checkpoint, so\n"
      "# resubmitting the script (or requeueing a task) is safe. Afterwards, build the tables and the report:\n"
      "#   sbatch --dependency=afterany:<this job id> {}\n",
      run_count, config.name, (o.out_dir / "slurm" / "collect.sbatch").string());
  s += "set -euo pipefail\n";
  s += fmt::format("D2GS={}\nOUT={}\n", shell_quote(o.program.string()), shell_quote(o.out_dir.string()));
  s += "export OMP_NUM_THREADS=\"${SLURM_CPUS_PER_TASK:-1}\"\n";
  s += "exec \"$D2GS\" experiment -o \"$OUT\" --run-index \"$SLURM_ARRAY_TASK_ID\"\n";
  return s;
}

std::string slurm_collect_script(const ExperimentConfig& config, const SlurmOptions& o) {
  check(o);
  std::string s = common_header(config, o, "-collect");
  s += fmt::format("#SBATCH --cpus-per-task={}\n", o.cpus);
  if (!o.mem.empty()) s += fmt::format("#SBATCH --mem={}\n", o.mem);
  s += fmt::format("#SBATCH --time={}\n", o.time);
  s += fmt::format("#SBATCH --output={}\n", (o.out_dir / "logs" / "slurm-collect-%j.out").string());
  s += "# Tables (tables/results.{md,csv}), IMR per method and report.html from the shared folder.\n";
  s += "set -euo pipefail\n";
  s += fmt::format("D2GS={}\nOUT={}\n", shell_quote(o.program.string()), shell_quote(o.out_dir.string()));
  s += "export OMP_NUM_THREADS=\"${SLURM_CPUS_PER_TASK:-1}\"\n";
  s += "exec \"$D2GS\" experiment collect -o \"$OUT\"\n";
  return s;
}

void write_slurm_scripts(const ExperimentConfig& config, std::size_t run_count, const SlurmOptions& o) {
  const std::string runs = slurm_array_script(config, run_count, o);
  const std::string collect = slurm_collect_script(config, o);
  for (const auto& [name, text] : {std::pair{"runs.sbatch", &runs}, std::pair{"collect.sbatch", &collect}}) {
    const fs::path path = o.out_dir / "slurm" / name;
    write_file_atomic(path, *text);
    fs::permissions(path, fs::perms::owner_exec | fs::perms::group_exec | fs::perms::others_exec,
                    fs::perm_options::add);
  }
}

}  // namespace d2gs::experiment
