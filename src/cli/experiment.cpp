// d2gs experiment: methods × scenes × view counts × seeds, one run folder each, resumable, run locally in
// parallel (--jobs) or as a Slurm job array (--emit-slurm, --run-index); `collect` builds the tables and
// the report from the experiment folder.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <string>

#include "cli/commands.hpp"
#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/log.hpp"
#include "d2gs/experiment/collect.hpp"
#include "d2gs/experiment/run_state.hpp"
#include "d2gs/experiment/runner.hpp"
#include "d2gs/experiment/slurm.hpp"
#include "d2gs/scene/split.hpp"
#include "d2gs/train/config.hpp"

namespace d2gs::cli {
namespace {
namespace fs = std::filesystem;

struct ExperimentOptions {
  std::string config;
  std::string out;
  std::string data_root;
  int jobs = 1;
  int run_index = -1;
  bool list = false;
  bool collect = false;
  bool no_imr = false;
  bool emit_slurm = false;
  experiment::SlurmOptions slurm;
  bool slurm_given = false;  // any --slurm-* option on the command line
};

void print_collect(const experiment::CollectResult& r) {
  std::printf("%s\n", r.markdown.c_str());
  std::printf("%d of %d runs finished\nwritten %s\nwritten %s\n", r.finished, r.total, r.markdown_path.c_str(),
              r.csv_path.c_str());
  if (!r.report_path.empty()) std::printf("written %s\n", r.report_path.c_str());
}

int run_experiment_command(const ExperimentOptions& o) {
  // One mode at a time; --jobs only where runs are trained.
  const int modes = int(o.list) + int(o.collect) + int(o.emit_slurm) + int(o.run_index >= 0);
  if (modes > 1)
    fail("options --list, --collect (or collect), --emit-slurm and --run-index are different modes: give one of them");
  if (o.jobs != 1 && (o.list || o.collect || o.emit_slurm || o.run_index >= 0))
    fail("option --jobs applies to training the runs here; with {} it does nothing",
         o.list ? "--list" : o.collect ? "--collect" : o.emit_slurm ? "--emit-slurm" : "--run-index (one run)");
  if (o.slurm_given && !o.emit_slurm) fail("the --slurm-* options apply to --emit-slurm only");
  const fs::path out = fs::absolute(o.out).lexically_normal();
  check_output_folder(out);  // an -o under a file fails now, not after the runs
  const auto progress = [](const std::string& line) { spdlog::info("experiment: {}", line); };
  experiment::ExperimentConfig config;
  std::vector<experiment::RunSpec> runs;
  if (!o.config.empty()) {
    // The folder's experiment.json is the runner's own state, rewritten below: an experiment file kept
    // there would be replaced by the state (and then no longer load as an experiment file).
    std::error_code ec;
    if (fs::exists(out / "experiment.json") && fs::equivalent(o.config, out / "experiment.json", ec))
      fail_file(o.config, "is where the folder -o keeps the experiment's state, which the runner rewrites; keep the "
                          "experiment file outside that folder, or give -o alone to use the stored experiment");
    config = experiment::load_experiment_config(o.config, o.data_root);
    runs = experiment::expand_runs(config, out);
    // A folder holding another experiment's state is not re-pointed at this one (its finished runs would
    // drop out of the tables); an edited file of the same experiment (more seeds, another method) is fine.
    if (fs::exists(out / "experiment.json", ec)) {
      const auto stored = experiment::read_experiment_state(out);
      if (stored.first.name != config.name)
        fail_file(out, "holds experiment '{}' (from {}), not '{}' of {}: give each experiment its own folder",
                  stored.first.name, stored.first.file.string(), config.name, o.config);
      // A Slurm task (--run-index) trains run I of the list the array was made from: the folder's.
      if (o.run_index >= 0) {
        bool same = stored.second.size() == runs.size();
        for (std::size_t k = 0; same && k < runs.size(); ++k) same = stored.second[k].id() == runs[k].id();
        if (!same)
          fail_file(o.config, "gives other runs than the experiment in {} (its run {} would be another): update the "
                    "folder with the whole experiment once (--config without --run-index, or --emit-slurm), then "
                    "its tasks", out.string(), o.run_index);
      }
    } else if (!o.list && fs::is_directory(out, ec)) {
      // A folder without the runner's state is another program's, or a training run's: the runner would
      // write its tables, report.html and logs into it over whatever is there.
      for (const auto& e : fs::directory_iterator(out, ec)) {
        const std::string name = e.path().filename().string();
        if (!(name.starts_with(".d2gs-") && name.ends_with(".lock")))
          fail_file(out, "is not empty and holds no d2gs experiment (no experiment.json; {} is there): refusing to "
                         "write into it (choose a new or empty folder)",
                    name);
      }
    }
  } else {
    if (!o.data_root.empty()) fail("option --data-root needs --config");
    std::tie(config, runs) = experiment::read_experiment_state(out);
  }
  // A finished run trained otherwise than the experiment now says is refused before anything is written,
  // trained or tabulated (--list shows it in the run's status instead).
  if (!o.list) {
    const bool one = o.run_index >= 0 && o.run_index < static_cast<int>(runs.size());
    experiment::check_finished_runs_match(
        out, one ? std::vector<experiment::RunSpec>{runs[static_cast<std::size_t>(o.run_index)]} : runs);
  }
  if (o.run_index >= static_cast<int>(runs.size()))
    fail("option --run-index {} is outside the experiment's {} runs (0..{})", o.run_index, runs.size(), runs.size() - 1);
  // Runs trained here need their scenes: a scene folder that is not there would fail every run of it, one
  // by one, after the folder, logs, tables and report were made (--list, --collect and --emit-slurm, which
  // may run where the data is not mounted, do not need them).
  if (!o.list && !o.collect && !o.emit_slurm)
    for (const auto& scene : config.scenes) {
      std::error_code ec;
      const bool needed = std::any_of(runs.begin(), runs.end(), [&](const experiment::RunSpec& r) {
        return r.scene == scene.name && (o.run_index < 0 || r.index == o.run_index);
      });
      if (needed && !fs::is_directory(scene.source, ec))
        fail_file(config.file, "scene '{}': its source {} is not a folder here (check data_root, or --data-root)",
                  scene.name, scene.source);
    }
  // ... and the views they ask for: a view count the scene cannot give (or explicit views it lacks) would
  // also fail each of its runs in turn. Scene metadata only (cameras; no image decoded), once per scene and
  // load options.
  if (!o.list && !o.collect && !o.emit_slurm) {
    std::map<std::string, Scene> scenes;
    for (const auto& r : runs) {
      if (o.run_index >= 0 && r.index != o.run_index) continue;
      try {
        TrainConfig c;
        update_from_json(c, r.train_config);
        const SceneLoadOptions load = scene_load_options(c);
        const std::string key = fmt::format("{}|{}|{}|{}", c.source, load.resolution, to_string(load.image_source),
                                            c.white_background);
        auto it = scenes.find(key);
        if (it == scenes.end()) it = scenes.emplace(key, load_scene(c.source, load)).first;
        make_split(it->second, split_options(c));
      } catch (const Error& e) {
        fail_file(config.file, "run {} ({}): {}", r.index, r.id(), e.what());
      }
    }
  }
  // --list changes nothing; the other modes keep the folder's state the experiment file's.
  if (!o.config.empty() && !o.list && (o.run_index < 0 || !fs::exists(out / "experiment.json")))
    experiment::write_experiment_state(out, config, runs);

  experiment::CollectOptions co;
  co.imr = !o.no_imr;
  co.progress = progress;
  if (o.collect) {
    print_collect(experiment::collect(config, runs, out, co));
    return 0;
  }
  if (o.emit_slurm) {
    experiment::SlurmOptions s = o.slurm;
    s.out_dir = out;
    if (s.program.empty()) s.program = fs::read_symlink("/proc/self/exe");
    s.program = fs::absolute(s.program);
    experiment::write_slurm_scripts(config, runs.size(), s);
    std::printf("%zu runs; written %s and %s\nsubmit with:\n  jobid=$(sbatch --parsable %s)\n"
                "  sbatch --dependency=afterany:$jobid %s\n",
                runs.size(), (out / "slurm/runs.sbatch").c_str(), (out / "slurm/collect.sbatch").c_str(),
                (out / "slurm/runs.sbatch").c_str(), (out / "slurm/collect.sbatch").c_str());
    return 0;
  }
  if (o.list) {
    std::map<experiment::RunPhase, int> count;
    std::printf("%-5s %-48s %s\n", "index", "run", "status");
    for (const auto& r : runs) {
      const experiment::RunState state = experiment::inspect_run(out, r);
      ++count[state.phase];
      std::printf("%-5d %-48s %s\n", r.index, r.dir.string().c_str(), experiment::describe(state).c_str());
    }
    std::string summary;
    for (const auto phase : {experiment::RunPhase::Finished, experiment::RunPhase::Running,
                             experiment::RunPhase::Interrupted, experiment::RunPhase::Failed,
                             experiment::RunPhase::Pending})
      summary += fmt::format("{}{} {}", summary.empty() ? "" : ", ", count[phase], experiment::to_string(phase));
    std::printf("%zu runs: %s\n", runs.size(), summary.c_str());
    return 0;
  }

  experiment::RunnerOptions ro;
  ro.jobs = o.jobs;
  ro.keep_checkpoints = config.keep_checkpoints;
  ro.progress = progress;
  std::vector<experiment::RunSpec> todo = runs;
  if (o.run_index >= 0) {
    todo = {runs[static_cast<std::size_t>(o.run_index)]};  // in range: checked above
    ro.jobs = 1;
  }
  const auto outcomes = experiment::run_all(todo, out, ro);
  int failed = 0, trained = 0, skipped = 0;
  std::string failures;
  for (const auto& oc : outcomes) {
    if (oc.status == experiment::RunStatus::Failed) {
      ++failed;
      failures += fmt::format("\n  run {} {}: {} (log: {})", oc.index, oc.id, oc.message,
                              (out / "logs" / (oc.id + ".log")).string());
    } else if (oc.status == experiment::RunStatus::Finished) {
      ++trained;
    } else {
      ++skipped;
    }
  }
  std::printf("experiment %s: %d trained, %d skipped, %d failed\n", config.name.c_str(), trained, skipped, failed);
  if (o.run_index < 0) print_collect(experiment::collect(config, runs, out, co));
  if (failed > 0) {
    std::fprintf(stderr, "failed runs:%s\n", failures.c_str());
    fail("experiment {}: {} of {} runs failed (the others are done; rerun the same command to retry)", config.name,
         failed, outcomes.size());
  }
  return 0;
}

}  // namespace

Run add_experiment_command(CLI::App& app) {
  auto o = std::make_shared<ExperimentOptions>();
  auto* cmd = app.add_subcommand("experiment", "Run methods × scenes × view counts × seeds and tabulate them");
  cmd->footer(
      "Runs go to DIR/runs/<scene>/<views>v/<method>[-<variant>]/seed<k> (logs: DIR/logs/, per-run configs:\n"
      "DIR/configs/). Finished runs (results.json) are skipped; an interrupted run resumes from its last\n"
      "checkpoint. Tables: DIR/tables/results.{md,csv}; report: DIR/report.html. Example configs:\n"
      "configs/experiments/. Example: d2gs experiment --config configs/experiments/llff_fern_3views.json -o out/fern --jobs 2");
  add_option(*cmd, "--config", o->config, "Experiment file (JSON); without it, DIR/experiment.json is used");
  add_option(*cmd, "-o,--output", o->out, "Experiment folder (required)");
  add_option(*cmd, "--data-root", o->data_root, "Folder the scene sources are relative to (overrides data_root)");
  add_option(*cmd, "-j,--jobs", o->jobs, "Runs trained at once on this machine (child processes)")
      ->check(in_range(1, 256))
      ->capture_default_str();
  add_option(*cmd, "--run-index", o->run_index, "Train only run I (a Slurm array task), without collecting")
      ->check(at_least(0));
  cmd->add_flag("--list", o->list,
                "Print the run list and where each run stands (finished with its scores, running with its "
                "iteration and time left, interrupted with the checkpoint it resumes from, failed with its "
                "error, pending), run nothing");
  cmd->add_flag("--collect", o->collect, "Only build the tables and the report from the folder");
  cmd->add_flag("--no-imr", o->no_imr, "Skip the IMR computation when collecting");
  cmd->add_flag("--emit-slurm", o->emit_slurm, "Write DIR/slurm/{runs,collect}.sbatch (a job array), run nothing");
  add_option(*cmd, "--slurm-partition", o->slurm.partition, "Slurm partition");
  add_option(*cmd, "--slurm-account", o->slurm.account, "Slurm account");
  add_option(*cmd, "--slurm-time", o->slurm.time, "Time limit per run")->capture_default_str();
  add_option(*cmd, "--slurm-cpus", o->slurm.cpus, "CPUs per run")->capture_default_str();
  add_option(*cmd, "--slurm-gpus", o->slurm.gpus, "GPUs per run (--gres=gpu:N)")->capture_default_str();
  add_option(*cmd, "--slurm-mem", o->slurm.mem, "Memory per run, e.g. 16G");
  add_option(*cmd, "--slurm-max-parallel", o->slurm.max_parallel, "Array throttle: at most N runs at once");
  add_option(*cmd, "--slurm-program", o->slurm.program, "d2gs program path on the cluster (default: this one)");

  auto* collect = cmd->add_subcommand("collect", "Build the tables and the report of an experiment folder");
  auto collect_out = std::make_shared<std::string>();
  auto collect_no_imr = std::make_shared<bool>(false);
  add_option(*collect, "-o,--output", *collect_out, "Experiment folder")->required();
  collect->add_flag("--no-imr", *collect_no_imr, "Skip the IMR computation");
  cmd->require_subcommand(0, 1);

  return [o, cmd, collect, collect_out, collect_no_imr]() -> int {
    ExperimentOptions opts = *o;
    for (const char* flag : {"--slurm-partition", "--slurm-account", "--slurm-time", "--slurm-cpus", "--slurm-gpus",
                             "--slurm-mem", "--slurm-max-parallel", "--slurm-program"})
      opts.slurm_given = opts.slurm_given || cmd->count(flag) > 0;
    if (collect->parsed()) {
      opts.out = *collect_out;
      opts.collect = true;
      opts.no_imr = opts.no_imr || *collect_no_imr;
    }
    if (opts.out.empty()) fail("experiment: option -o/--output (the experiment folder) is required");
    return run_experiment_command(opts);
  };
}

}  // namespace d2gs::cli
