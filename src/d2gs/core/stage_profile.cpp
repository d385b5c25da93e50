#include "d2gs/core/stage_profile.hpp"

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <cstring>
#include <mutex>

#include <fmt/format.h>

namespace d2gs::profile {
namespace {

std::atomic<bool>& flag() {
  static std::atomic<bool> on = [] {
    const char* env = std::getenv("D2GS_PROFILE");
    return env != nullptr && *env != '\0' && std::strcmp(env, "0") != 0;
  }();
  return on;
}

struct Registry {
  std::mutex mutex;
  std::vector<StageTotal> stages;
};

Registry& registry() {
  static Registry r;
  return r;
}

}  // namespace

bool enabled() { return flag().load(std::memory_order_relaxed); }
void set_enabled(bool on) { flag().store(on, std::memory_order_relaxed); }

void record(const char* stage, double seconds) {
  Registry& r = registry();
  const std::lock_guard lock(r.mutex);
  auto it = std::find_if(r.stages.begin(), r.stages.end(), [&](const StageTotal& s) { return s.stage == stage; });
  if (it == r.stages.end()) it = r.stages.insert(r.stages.end(), StageTotal{stage, 0.0, 0});
  it->seconds += seconds;
  ++it->calls;
}

std::vector<StageTotal> totals() {
  Registry& r = registry();
  const std::lock_guard lock(r.mutex);
  return r.stages;
}

void reset() {
  Registry& r = registry();
  const std::lock_guard lock(r.mutex);
  r.stages.clear();
}

std::string format_table(const std::vector<StageTotal>& stages, const std::string& whole) {
  const auto w = std::find_if(stages.begin(), stages.end(), [&](const StageTotal& s) { return s.stage == whole; });
  if (w == stages.end() || w->calls == 0) return {};
  const double per = 1e3 / static_cast<double>(w->calls);
  const double total = w->seconds;
  std::string out = fmt::format("{:<34} {:>10} {:>8} {:>7}\n", "stage", "ms/" + whole, "calls", "share");
  double covered = 0.0;
  for (const StageTotal& s : stages) {
    if (s.stage == whole) continue;
    // "A / B" is a part of stage A: listed, not added again. Parts are recorded before their stage ends,
    // so a stage's parts are gathered under it here.
    if (s.stage.find(" / ") != std::string::npos) continue;
    covered += s.seconds;
    out += fmt::format("{:<34} {:>10.3f} {:>8} {:>6.1f}%\n", s.stage, s.seconds * per, s.calls,
                       total > 0 ? 100.0 * s.seconds / total : 0.0);
    for (const StageTotal& part : stages)
      if (part.stage.size() > s.stage.size() + 3 && part.stage.compare(0, s.stage.size() + 3, s.stage + " / ") == 0)
        out += fmt::format("  {:<32} {:>10.3f} {:>8} {:>6.1f}%\n", part.stage.substr(s.stage.size() + 3),
                           part.seconds * per, part.calls, total > 0 ? 100.0 * part.seconds / total : 0.0);
  }
  out += fmt::format("{:<34} {:>10.3f} {:>8} {:>6.1f}%\n", "other", (total - covered) * per, "",
                     total > 0 ? 100.0 * (total - covered) / total : 0.0);
  out += fmt::format("{:<34} {:>10.3f} {:>8} {:>6.1f}%\n", whole, total * per, w->calls, 100.0);
  return out;
}

}  // namespace d2gs::profile
