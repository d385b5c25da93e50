// Checked JSON numbers (core/json_value.hpp): never truncated, never wrapped, the key named.
#include <cstdint>
#include <limits>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/error.hpp"
#include "d2gs/core/json_value.hpp"

namespace d2gs {
namespace {

using nlohmann::json;

// The message of the d2gs::Error thrown by f, or "" when none is.
template <typename F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(JsonValue, IntegersInRangeAreTaken) {
  EXPECT_EQ(json_number<int>(json::parse("2147483647"), "k"), 2147483647);
  EXPECT_EQ(json_number<int>(json::parse("-2147483648"), "k"), -2147483647 - 1);
  EXPECT_EQ(json_number<int>(json::parse("8"), "k", 1, 8), 8);
  EXPECT_EQ(json_number<std::uint64_t>(json::parse("18446744073709551615"), "seed"),
            std::numeric_limits<std::uint64_t>::max());
  EXPECT_EQ(json_number<std::size_t>(json::parse("0"), "samples"), 0u);
  EXPECT_EQ(json_number<std::int64_t>(json::parse("-9223372036854775808"), "k"), std::numeric_limits<std::int64_t>::min());
}

TEST(JsonValue, IntegersOutOfTheirTypeAreRefusedNotWrapped) {
  // 4294967301 = 2^32 + 5: get<int>() gives 5.
  const std::string wrap = error_of([] { json_number<int>(json::parse("4294967301"), "iterations"); });
  EXPECT_NE(wrap.find("key 'iterations'"), std::string::npos) << wrap;
  EXPECT_NE(wrap.find("4294967301 is out of range"), std::string::npos) << wrap;
  EXPECT_NE(error_of([] { json_number<int>(json::parse("-2147483649"), "k"); }).find("out of range"), std::string::npos);
  // A negative seed would wrap to 2^64 − 1.
  const std::string neg = error_of([] { json_number<std::uint64_t>(json::parse("-1"), "seed"); });
  EXPECT_NE(neg.find("key 'seed': -1 is out of range"), std::string::npos) << neg;
  // Above 2^64 − 1 nlohmann stores a float: not an integer any more.
  EXPECT_NE(error_of([] { json_number<std::uint64_t>(json::parse("18446744073709551616"), "seed"); }), "");
  // The caller's range.
  EXPECT_NE(error_of([] { json_number<int>(json::parse("0"), "every", 1, 100); }).find("expected 1..100"), std::string::npos);
  EXPECT_NE(error_of([] { json_number<int>(json::parse("101"), "every", 1, 100); }), "");
  EXPECT_NE(error_of([] { json_number<std::uint64_t>(json::parse("3"), "k", 5, 9); }), "");
}

TEST(JsonValue, FractionsAndOtherTypesAreNotIntegers) {
  const std::string frac = error_of([] { json_number<int>(json::parse("5.7"), "iterations"); });
  EXPECT_NE(frac.find("key 'iterations' must be an integer, got 5.7"), std::string::npos) << frac;
  EXPECT_NE(error_of([] { json_number<int>(json::parse("5.0"), "k"); }).find("must be an integer"), std::string::npos);
  const std::string str = error_of([] { json_number<int>(json::parse("\"5\""), "k"); });
  EXPECT_NE(str.find("must be an integer, got string"), std::string::npos) << str;
  EXPECT_NE(error_of([] { json_number<int>(json::parse("true"), "k"); }), "");
  EXPECT_NE(error_of([] { json_number<int>(json::parse("null"), "k"); }), "");
}

TEST(JsonValue, FloatingValuesMustBeFiniteNumbersWithinTheirType) {
  EXPECT_DOUBLE_EQ(json_number<double>(json::parse("5"), "tau"), 5.0);
  EXPECT_FLOAT_EQ(json_number<float>(json::parse("1.6e-4"), "lr"), 1.6e-4f);
  // 1e39 is a double but no float.
  EXPECT_NE(error_of([] { json_number<float>(json::parse("1e39"), "lr"); }).find("out of range"), std::string::npos);
  EXPECT_NE(error_of([] { json_number<double>(json::parse("\"0.1\""), "tau"); }).find("must be a number"),
            std::string::npos);
  EXPECT_NE(error_of([] { json_number<double>(json::parse("0.5"), "p", 0.0, 0.25); }), "");
  // nlohmann parses an overflowing literal to infinity.
  const json inf = json(std::numeric_limits<double>::infinity());
  EXPECT_NE(error_of([&] { json_number<double>(inf, "x"); }).find("finite"), std::string::npos);
}

TEST(JsonValue, ListsNameTheBadElement) {
  EXPECT_EQ(json_number_list<int>(json::parse("[3, 6, 9]"), "views", 0), (std::vector<int>{3, 6, 9}));
  const std::string bad = error_of([] { json_number_list<int>(json::parse("[3, 4294967299]"), "views", 0); });
  EXPECT_NE(bad.find("key 'views[1]': 4294967299 is out of range"), std::string::npos) << bad;
  EXPECT_NE(error_of([] { json_number_list<int>(json::parse("[1, 2.5]"), "views"); }).find("views[1]"), std::string::npos);
  EXPECT_NE(error_of([] { json_number_list<int>(json::parse("[-1]"), "views", 0); }), "");
  EXPECT_NE(error_of([] { json_number_list<int>(json::parse("3"), "views"); }).find("must be a list"), std::string::npos);
}

// nlohmann keeps the last of two equal keys; parse_json refuses the file, naming the key and where it is.
TEST(JsonValue, DuplicateKeysAreRefusedWithTheirPath) {
  const std::string top = error_of([] { parse_json(R"({"camera_angle_x": 0.5, "frames": [], "camera_angle_x": 0.7})", "t.json"); });
  EXPECT_NE(top.find("t.json: duplicate key 'camera_angle_x'"), std::string::npos) << top;
  EXPECT_EQ(top.find(" in "), std::string::npos) << top;  // at the top: no path
  const std::string nested = error_of([] {
    parse_json(R"({"frames": [{"file_path": "a"}, [1, {"x": 1}], {"file_path": "b", "file_path": "c"}]})", "t.json");
  });
  EXPECT_NE(nested.find("t.json: duplicate key 'file_path' in frames[2]"), std::string::npos) << nested;
  const std::string deep = error_of([] { parse_json(R"({"a": {"b": [0, {"c": 1, "c": 2}]}})", "d.json"); });
  EXPECT_NE(deep.find("duplicate key 'c' in a.b[1]"), std::string::npos) << deep;
  // A key with binary bytes is shown escaped.
  const std::string binary = error_of([] { parse_json("{\"k\\u0000\": 1, \"k\\u0000\": 2}", "b.json"); });
  EXPECT_NE(binary.find("duplicate key 'k\\x00'"), std::string::npos) << binary;
  // The same key in different objects, and equal values under different keys, are fine.
  const json ok = parse_json(R"({"frames": [{"file_path": "a", "m": [[1]]}, {"file_path": "b", "m": [[1]]}], "m": 1})", "ok.json");
  EXPECT_EQ(ok["frames"][1]["file_path"], "b");
  EXPECT_EQ(ok["m"], 1);
  EXPECT_NE(error_of([] { parse_json("{\"a\": 1,", "s.json"); }).find("s.json: invalid JSON"), std::string::npos);
}

}  // namespace
}  // namespace d2gs
