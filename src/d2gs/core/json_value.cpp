#include "d2gs/core/json_value.hpp"

#include <algorithm>
#include <set>

#include "d2gs/core/atomic_file.hpp"

namespace d2gs {

namespace {

// Where the parser is: one entry per open object or array, with the keys an object has had so far (a
// second one is an error: nlohmann keeps the last, silently) and the position of the value being read.
class KeyTracker {
public:
  explicit KeyTracker(const std::filesystem::path& source) : source_(source) {}

  bool operator()(int /*depth*/, nlohmann::json::parse_event_t event, nlohmann::json& parsed) {
    using Event = nlohmann::json::parse_event_t;
    switch (event) {
      case Event::object_start: open_.push_back({true, {}, {}, 0}); break;
      case Event::array_start: open_.push_back({false, {}, {}, 0}); break;
      case Event::key: {
        Level& level = open_.back();
        level.key = parsed.get<std::string>();
        if (!level.keys.insert(level.key).second) {
          const std::string where = path(open_.size() - 1);
          fail_file(source_, "duplicate key '{}'{}{} (JSON keeps only one of them)", printable(level.key),
                    where.empty() ? "" : " in ", where);
        }
        break;
      }
      case Event::object_end:
      case Event::array_end:
        open_.pop_back();
        value_done();
        break;
      case Event::value: value_done(); break;
    }
    return true;
  }

private:
  struct Level {
    bool is_object;
    std::set<std::string> keys;
    std::string key;    // objects: the key of the value being read
    std::size_t index;  // arrays: the index of the value being read
  };
  void value_done() {
    if (!open_.empty() && !open_.back().is_object) ++open_.back().index;
  }
  // The path of the value the first `levels` open containers are reading, e.g. frames[3].
  std::string path(std::size_t levels) const {
    std::string out;
    for (std::size_t i = 0; i < levels; ++i) {
      if (open_[i].is_object) out += (out.empty() ? "" : ".") + printable(open_[i].key);
      else out += fmt::format("[{}]", open_[i].index);
    }
    return out;
  }
  const std::filesystem::path& source_;
  std::vector<Level> open_;
};

}  // namespace

nlohmann::json parse_json(std::string_view text, const std::filesystem::path& source) {
  try {
    return nlohmann::json::parse(text.begin(), text.end(), KeyTracker(source));
  } catch (const nlohmann::json::exception& e) {
    // nlohmann's messages may quote input containing newlines; errors are one line.
    std::string what = e.what();
    std::replace_if(what.begin(), what.end(), [](char c) { return c == '\n' || c == '\r'; }, ' ');
    fail_file(source, "invalid JSON ({})", what);
  }
}

nlohmann::json read_json_file(const std::filesystem::path& path) { return parse_json(read_file(path), path); }

}  // namespace d2gs
