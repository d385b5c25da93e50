#pragma once
// Paths every test may use, and a scratch folder per test.
#include <sys/resource.h>
#include <sys/wait.h>

#include <chrono>
#include <csignal>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <string>
#include <thread>

#include <fmt/format.h>
#include <gtest/gtest.h>

namespace d2gs::test {

inline std::filesystem::path source_dir() { return D2GS_SOURCE_DIR; }
// The real scenes of ../shared/data (fern, room, lego). Tests fail if they are missing: CI has them.
inline std::filesystem::path shared_data() { return D2GS_SHARED_DATA_DIR; }
inline std::filesystem::path cli_path() { return D2GS_CLI_PATH; }

// A fresh empty folder for the running test, removed at the start of the next run with that name. One
// folder per build (the d2gs program's folder, hashed), so that two checkouts' test suites running at once on one
// machine (a clone's CI beside a working tree) do not delete each other's files.
inline std::filesystem::path scratch_dir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::size_t binary = std::hash<std::string>{}(std::filesystem::path(D2GS_CLI_PATH).parent_path().string());
  auto dir = std::filesystem::temp_directory_path() / "d2gs-tests" / fmt::format("{:08x}", binary & 0xffffffffu) /
             (std::string(info->test_suite_name()) + "." + info->name());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

// How many times `what` occurs in `s` (non-overlapping).
inline std::size_t count_occurrences(const std::string& s, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t p = 0; (p = s.find(what, p)) != std::string::npos; p += what.size()) ++n;
  return n;
}

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
};

// Runs the d2gs program with the given argument string (shell syntax) and captures its output.
inline CommandResult run_cli(const std::string& args) {
  CommandResult result;
  const std::string command = "'" + cli_path().string() + "' " + args + " 2>&1 </dev/null";
  FILE* pipe = ::popen(command.c_str(), "r");
  if (!pipe) return result;
  char buffer[4096];
  std::size_t n;
  while ((n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) result.output.append(buffer, n);
  const int status = ::pclose(pipe);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return result;
}

// run_cli with the files the program writes limited to `bytes` each (RLIMIT_FSIZE, SIGXFSZ ignored, both
// inherited): a write beyond it fails with EFBIG part-way, as on a full disk.
inline CommandResult run_cli_with_file_size_limit(const std::string& args, std::size_t bytes) {
  rlimit saved{};
  ::getrlimit(RLIMIT_FSIZE, &saved);
  rlimit small = saved;
  small.rlim_cur = bytes;
  const auto previous = std::signal(SIGXFSZ, SIG_IGN);
  ::setrlimit(RLIMIT_FSIZE, &small);
  CommandResult result = run_cli(args);
  ::setrlimit(RLIMIT_FSIZE, &saved);
  std::signal(SIGXFSZ, previous);
  return result;
}

// Starts `command` (shell syntax; redirect its output) in the background and returns its process id
// (0 if it could not be started).
inline int start_in_background(const std::string& command) {
  FILE* pipe = ::popen((command + " & echo $!").c_str(), "r");
  if (!pipe) return 0;
  int pid = 0;
  if (std::fscanf(pipe, "%d", &pid) != 1) pid = 0;
  ::pclose(pipe);
  return pid;
}

// Polls `done` every 20 ms until it holds or `limit` has passed; returns its last value.
inline bool wait_until(const std::function<bool()>& done, std::chrono::seconds limit = std::chrono::minutes(5)) {
  const auto deadline = std::chrono::steady_clock::now() + limit;
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return done();
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return true;
}

}  // namespace d2gs::test
