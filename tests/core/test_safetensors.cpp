// safetensors: round trip, the Python-written fixture (F16 data), and one clean error per kind of damage.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/safetensors.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {

// A file made by hand: header JSON and data bytes as given.
std::string raw_file(const std::string& header, const std::string& data) {
  std::string out(8, '\0');
  const std::uint64_t n = header.size();
  std::memcpy(out.data(), &n, 8);
  return out + header + data;
}

std::string f32_bytes(std::initializer_list<float> v) {
  std::string out;
  for (float f : v) out.append(reinterpret_cast<const char*>(&f), 4);
  return out;
}

std::string error_of(const std::string& bytes) {
  try {
    parse_safetensors(bytes, "w.safetensors");
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(Safetensors, RoundTripKeepsNamesShapesValuesAndMetadata) {
  const auto dir = test::scratch_dir();
  TensorFile f;
  f.tensors["b"] = {{2, 3}, {1, 2, 3, 4, 5, -6.5f}};
  f.tensors["a.weight"] = {{1}, {0.25f}};
  f.tensors["empty"] = {{0, 4}, {}};
  f.metadata["net"] = "vgg16";
  write_safetensors(dir / "t.safetensors", f);
  const std::string bytes = read_file(dir / "t.safetensors");
  std::uint64_t header_len;
  std::memcpy(&header_len, bytes.data(), 8);
  EXPECT_EQ((8 + header_len) % 8, 0u);  // header padded as the format asks
  const TensorFile g = read_safetensors(dir / "t.safetensors");
  ASSERT_EQ(g.tensors.size(), 3u);
  EXPECT_EQ(g.tensors.at("b").shape, (std::vector<std::int64_t>{2, 3}));
  EXPECT_EQ(g.tensors.at("b").values, f.tensors["b"].values);
  EXPECT_EQ(g.tensors.at("a.weight").values, std::vector<float>{0.25f});
  EXPECT_EQ(g.tensors.at("empty").numel(), 0u);
  EXPECT_EQ(g.metadata.at("net"), "vgg16");
}

TEST(Safetensors, ReadsF16AndF64Tensors) {
  // F16: 1.0 = 0x3c00, -2.5 = 0xc100, 2^-24 (smallest subnormal) = 0x0001; F64: 0.1.
  const std::string f16("\x00\x3c\x00\xc1\x01\x00", 6);
  double d = 0.1;
  const std::string f64(reinterpret_cast<const char*>(&d), 8);
  const auto t = parse_safetensors(
      raw_file(R"({"h":{"dtype":"F16","shape":[3],"data_offsets":[0,6]},"d":{"dtype":"F64","shape":[1],"data_offsets":[6,14]}})",
               f16 + f64),
      "x");
  EXPECT_EQ(t.tensors.at("h").values, (std::vector<float>{1.0f, -2.5f, std::ldexp(1.0f, -24)}));
  EXPECT_EQ(t.tensors.at("d").values, std::vector<float>{0.1f});
}

TEST(Safetensors, ReadsTheFixtureWrittenByPython) {
  // tools/make_lpips_fixtures.py writes this file (F16 data) with its own writer.
  const auto f = read_safetensors(test::source_dir() / "tests/eval/fixtures/lpips/vgg16_w8.safetensors");
  EXPECT_EQ(f.metadata.at("net"), "vgg16");
  EXPECT_EQ(f.metadata.at("format"), "d2gs-lpips");
  EXPECT_EQ(f.tensors.at("features.0.weight").shape, (std::vector<std::int64_t>{8, 3, 3, 3}));
  EXPECT_EQ(f.tensors.at("features.28.weight").shape, (std::vector<std::int64_t>{64, 64, 3, 3}));
  EXPECT_EQ(f.tensors.at("lin4.weight").shape, (std::vector<std::int64_t>{1, 64, 1, 1}));
  EXPECT_EQ(f.tensors.size(), 26u + 5u);
}

TEST(Safetensors, DamagedFilesGiveOneLineErrorsNamingTheFile) {
  const std::string good_header = R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[0,8]}})";
  EXPECT_NO_THROW(parse_safetensors(raw_file(good_header, f32_bytes({1, 2})), "w"));
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"abc", "too short"},
      {raw_file(good_header, f32_bytes({1, 2})).substr(0, 20), "exceeds the file size"},
      {raw_file("not json", ""), "not JSON"},
      {raw_file("[1,2]", ""), "not a JSON object"},
      {raw_file(good_header, f32_bytes({1})), "outside"},  // truncated data
      {raw_file(R"({"a":{"dtype":"I64","shape":[1],"data_offsets":[0,8]}})", f32_bytes({1, 2})), "unsupported dtype"},
      {raw_file(R"({"a":{"dtype":"F32","shape":[3],"data_offsets":[0,8]}})", f32_bytes({1, 2})), "12 expected"},
      {raw_file(R"({"a":{"dtype":"F32","shape":[-1],"data_offsets":[0,8]}})", f32_bytes({1, 2})), "bad shape"},
      {raw_file(R"({"a":{"dtype":"F32","shape":[2]}})", f32_bytes({1, 2})), "data_offsets"},
      {raw_file(R"({"a":{"dtype":"F32","shape":[1],"data_offsets":[0,4]},"b":{"dtype":"F32","shape":[1],"data_offsets":[2,6]}})",
                f32_bytes({1, 2})),
       "overlap"},
  };
  for (const auto& [bytes, expected] : cases) {
    const std::string msg = error_of(bytes);
    EXPECT_EQ(msg.rfind("w.safetensors: ", 0), 0u) << msg;
    EXPECT_NE(msg.find(expected), std::string::npos) << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  }
}

TEST(Safetensors, MissingFileNamesIt) {
  try {
    read_safetensors("/nonexistent/weights.safetensors");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/weights.safetensors"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace d2gs
