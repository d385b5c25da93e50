#pragma once
// Beyond one machine: a Slurm job-array script over an experiment's run list (task i trains run i into
// the shared experiment folder with `d2gs experiment -o DIR --run-index i`) and a collect script to
// submit after it (`--dependency=afterany:<array job>`), which builds the tables and the report.
#include <filesystem>
#include <string>

#include "d2gs/experiment/experiment_config.hpp"

namespace d2gs::experiment {

struct SlurmOptions {
  std::filesystem::path program;  // absolute path of the d2gs program on the cluster
  std::filesystem::path out_dir;  // absolute experiment folder (shared file system)
  std::string partition;          // empty: the cluster's default
  std::string account;
  std::string time = "02:00:00";  // per run
  int cpus = 8;
  int gpus = 0;          // --gres=gpu:N when > 0
  std::string mem;       // e.g. "16G"; empty: the default
  int max_parallel = 0;  // array throttle (%N); 0: none
};

// Single-quoted for a POSIX shell.
std::string shell_quote(const std::string& s);
std::string slurm_array_script(const ExperimentConfig& config, std::size_t run_count, const SlurmOptions& options);
std::string slurm_collect_script(const ExperimentConfig& config, const SlurmOptions& options);
// Writes DIR/slurm/runs.sbatch and DIR/slurm/collect.sbatch (atomically, executable).
void write_slurm_scripts(const ExperimentConfig& config, std::size_t run_count, const SlurmOptions& options);

}  // namespace d2gs::experiment
