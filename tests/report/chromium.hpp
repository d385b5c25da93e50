#pragma once
// Headless Chromium for the report tests: loads a page, returns the DOM after load (the page's own image
// check has run by then) and Chromium's log, console messages included. Needs no display; `timeout`
// bounds a hung browser (no DOM then, and the caller's assertions fail). scripts/setup.sh installs
// /usr/bin/chromium; callers skip where it is absent.
#include <cstdio>
#include <filesystem>
#include <string>

#include "d2gs/core/atomic_file.hpp"

namespace d2gs::test {

inline constexpr const char* kChromium = "/usr/bin/chromium";

// The DOM after load, as Chromium serialises it, and what Chromium logged (console messages included).
// Headless needs no display; `timeout` bounds a hung browser (no DOM then, and the test fails).
struct Loaded {
  std::string dom;
  std::string log;
};

inline Loaded load(const std::filesystem::path& page, const std::filesystem::path& profile) {
  const std::filesystem::path log = profile.string() + ".log";
  const std::string cmd = "timeout -k 10 90 " + std::string(kChromium) +
                          " --headless --no-sandbox --disable-gpu --disable-quic --no-first-run"
                          " --disable-background-networking --disable-component-update --disable-sync"
                          " --enable-logging=stderr --v=0"
                          " --user-data-dir='" + profile.string() + "' --dump-dom 'file://" + page.string() +
                          "' 2>'" + log.string() + "' </dev/null";
  Loaded out;
  FILE* pipe = ::popen(cmd.c_str(), "r");
  if (!pipe) return out;
  char buffer[65536];
  std::size_t n;
  while ((n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) out.dom.append(buffer, n);
  ::pclose(pipe);
  if (std::filesystem::exists(log)) out.log = read_file(log);
  return out;
}

// Console lines that mean the page itself went wrong (a script error, a resource that did not load).
inline std::string page_errors(const std::string& log) {
  std::string bad;
  std::size_t start = 0;
  while (start < log.size()) {
    std::size_t end = log.find('\n', start);
    if (end == std::string::npos) end = log.size();
    const std::string line = log.substr(start, end - start);
    if (line.find("CONSOLE") != std::string::npos &&
        (line.find("Uncaught") != std::string::npos || line.find("Failed to load") != std::string::npos ||
         line.find("Refused") != std::string::npos))
      bad += line + "\n";
    start = end + 1;
  }
  return bad;
}

}  // namespace d2gs::test
