// PLY model and point-cloud files (src/d2gs/model/ply.hpp).
#include "d2gs/model/ply.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {
namespace fs = std::filesystem;
using test::scratch_dir;
using test::source_dir;

constexpr float kMax = std::numeric_limits<float>::max();

fs::path fixture(const std::string& name) { return source_dir() / "tests" / "model" / "fixtures" / name; }

std::uint32_t bits(float v) { return std::bit_cast<std::uint32_t>(v); }

// Bit-exact comparison of every attribute.
void expect_bit_identical(const Gaussians& a, const Gaussians& b) {
  ASSERT_EQ(a.sh_degree, b.sh_degree);
  ASSERT_EQ(a.size(), b.size());
  const auto same = [](const std::vector<float>& x, const std::vector<float>& y, const char* name) {
    ASSERT_EQ(x.size(), y.size()) << name;
    for (std::size_t i = 0; i < x.size(); ++i)
      ASSERT_EQ(bits(x[i]), bits(y[i])) << name << "[" << i << "]: " << x[i] << " vs " << y[i];
  };
  same(a.means, b.means, "means");
  same(a.log_scales, b.log_scales, "log_scales");
  same(a.quats, b.quats, "quats");
  same(a.opacity_logits, b.opacity_logits, "opacity_logits");
  same(a.sh_dc, b.sh_dc, "sh_dc");
  same(a.sh_rest, b.sh_rest, "sh_rest");
}

// Random finite floats drawn from all bit patterns (so: denormals, huge values, both zeros), with
// explicit special values at the front.
Gaussians random_model(std::size_t n, int degree, std::uint32_t seed) {
  std::mt19937 rng(seed);
  Gaussians g;
  g.resize(n, degree);
  const auto fill = [&](std::vector<float>& a) {
    for (auto& v : a) {
      do v = std::bit_cast<float>(static_cast<std::uint32_t>(rng()));
      while (!std::isfinite(v));
    }
  };
  for (auto* a : {&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.sh_dc, &g.sh_rest}) fill(*a);
  if (n > 0) {
    g.means[0] = -0.0f;
    g.means[1] = std::numeric_limits<float>::denorm_min();
    g.means[2] = kMax;
    g.opacity_logits[0] = -kMax;
    g.sh_dc[0] = -std::numeric_limits<float>::denorm_min();
    g.log_scales[0] = 0.0f;
    g.quats[0] = std::numeric_limits<float>::min();  // smallest normal
  }
  return g;
}

// The model of tools/make_ply_fixture.py: attribute a, Gaussian i, per-Gaussian memory index m.
float fixture_value(std::size_t i, int a, std::size_t m) {
  const float big = kMax;
  if (i == 0 && a == 0 && m == 0) return -0.0f;
  if (i == 0 && a == 0 && m == 1) return std::ldexp(1.0f, -149);
  if (i == 0 && a == 0 && m == 2) return big;
  if (i == 1 && a == 1 && m == 2) return -std::ldexp(1.0f, -130);
  if (i == 1 && a == 3 && m == 0) return -big;
  const float v = static_cast<float>((static_cast<double>(i) + 1) * 1000 + a * 100 + static_cast<double>(m)) / 16.0f;
  return (i + static_cast<std::size_t>(a) + m) % 2 ? -v : v;
}

Gaussians fixture_model(std::size_t n, int degree) {
  Gaussians g;
  g.resize(n, degree);
  const auto fill = [&](std::vector<float>& arr, int a) {
    const std::size_t per = arr.size() / n;
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t m = 0; m < per; ++m) arr[i * per + m] = fixture_value(i, a, m);
  };
  fill(g.means, 0);
  fill(g.sh_dc, 1);
  fill(g.sh_rest, 2);
  fill(g.opacity_logits, 3);
  fill(g.log_scales, 4);
  fill(g.quats, 5);
  return g;
}

// ---- a small independent PLY writer for test inputs -------------------------------------------------

struct Prop {
  std::string name;
  std::string type = "float";
  std::string count_type;  // non-empty: a list property
};
struct Element {
  std::string name;
  std::vector<Prop> props;
  std::vector<std::vector<std::vector<double>>> rows;  // rows[item][prop] = values (lists: any length)
  std::string declared_count;                          // overrides the count in the header when set
};

template <typename T>
void put(std::string& out, double v, bool big_endian) {
  const T t = static_cast<T>(v);
  char b[sizeof(T)];
  std::memcpy(b, &t, sizeof(T));
  if (big_endian) std::reverse(b, b + sizeof(T));
  out.append(b, sizeof(T));
}

void put_value(std::string& out, const std::string& type, double v, const std::string& format) {
  if (format == "ascii") {
    if (type == "float" || type == "float32") out += fmt::format("{} ", static_cast<float>(v));
    else if (type == "double" || type == "float64") out += fmt::format("{} ", v);
    else out += fmt::format("{} ", static_cast<long long>(v));
    return;
  }
  const bool be = format == "binary_big_endian";
  if (type == "float" || type == "float32") put<float>(out, v, be);
  else if (type == "double" || type == "float64") put<double>(out, v, be);
  else if (type == "char" || type == "int8") put<std::int8_t>(out, v, be);
  else if (type == "uchar" || type == "uint8") put<std::uint8_t>(out, v, be);
  else if (type == "short" || type == "int16") put<std::int16_t>(out, v, be);
  else if (type == "ushort" || type == "uint16") put<std::uint16_t>(out, v, be);
  else if (type == "int" || type == "int32") put<std::int32_t>(out, v, be);
  else if (type == "uint" || type == "uint32") put<std::uint32_t>(out, v, be);
  else ADD_FAILURE() << "bad type " << type;
}

std::string make_ply(const std::string& format, const std::vector<Element>& elements, const std::string& eol = "\n",
                     const std::string& extra_header = "") {
  std::string out = "ply" + eol + "format " + format + " 1.0" + eol + "comment made by test_ply" + eol + extra_header;
  for (const auto& e : elements) {
    out += "element " + e.name + " " + (e.declared_count.empty() ? std::to_string(e.rows.size()) : e.declared_count) + eol;
    for (const auto& p : e.props)
      out += p.count_type.empty() ? "property " + p.type + " " + p.name + eol
                                  : "property list " + p.count_type + " " + p.type + " " + p.name + eol;
  }
  out += "end_header" + eol;
  for (const auto& e : elements)
    for (const auto& row : e.rows) {
      for (std::size_t p = 0; p < e.props.size(); ++p) {
        if (!e.props[p].count_type.empty()) put_value(out, e.props[p].count_type, static_cast<double>(row[p].size()), format);
        for (double v : row[p]) put_value(out, e.props[p].type, v, format);
      }
      if (format == "ascii") out += "\n";
    }
  return out;
}

// The columns of a model as the viewer layout names them (the file's channel-major f_rest order).
std::vector<std::pair<std::string, std::vector<double>>> model_columns(const Gaussians& g, bool normals = true) {
  std::vector<std::pair<std::string, std::vector<double>>> cols;
  const std::size_t n = g.size();
  const std::size_t k = static_cast<std::size_t>(g.sh_rest_count());
  const auto col = [&](const std::string& name, const std::function<float(std::size_t)>& get) {
    std::vector<double> v(n);
    for (std::size_t i = 0; i < n; ++i) v[i] = get(i);
    cols.emplace_back(name, std::move(v));
  };
  for (std::size_t j = 0; j < 3; ++j) col(std::string(1, "xyz"[j]), [&](std::size_t i) { return g.means[i * 3 + j]; });
  if (normals)
    for (const char* nn : {"nx", "ny", "nz"}) col(nn, [](std::size_t) { return 0.0f; });
  for (std::size_t j = 0; j < 3; ++j) col(fmt::format("f_dc_{}", j), [&](std::size_t i) { return g.sh_dc[i * 3 + j]; });
  for (std::size_t c = 0; c < 3; ++c)
    for (std::size_t j = 0; j < k; ++j)
      col(fmt::format("f_rest_{}", c * k + j), [&](std::size_t i) { return g.sh_rest[(i * k + j) * 3 + c]; });
  col("opacity", [&](std::size_t i) { return g.opacity_logits[i]; });
  for (std::size_t j = 0; j < 3; ++j) col(fmt::format("scale_{}", j), [&](std::size_t i) { return g.log_scales[i * 3 + j]; });
  for (std::size_t j = 0; j < 4; ++j) col(fmt::format("rot_{}", j), [&](std::size_t i) { return g.quats[i * 4 + j]; });
  return cols;
}

Element vertex_from_columns(const std::vector<std::pair<std::string, std::vector<double>>>& cols,
                            const std::string& type = "float") {
  Element e{"vertex", {}, {}, {}};
  const std::size_t n = cols.empty() ? 0 : cols[0].second.size();
  for (const auto& c : cols) e.props.push_back({c.first, type, ""});
  e.rows.assign(n, std::vector<std::vector<double>>(cols.size()));
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t p = 0; p < cols.size(); ++p) e.rows[i][p] = {cols[p].second[i]};
  return e;
}

// A model whose values are exact in every numeric type used below (small integers).
Gaussians integer_model(std::size_t n, int degree) {
  Gaussians g;
  g.resize(n, degree);
  int v = 0;
  for (auto* a : {&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.sh_dc, &g.sh_rest})
    for (auto& x : *a) x = static_cast<float>((v++ * 7) % 100);
  return g;
}

// Runs `f`, expects d2gs::Error with a one-line message containing every `needles` entry.
void expect_error(const std::function<void()>& f, const std::vector<std::string>& needles) {
  try {
    f();
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.find('\n'), std::string::npos) << "multi-line message: " << msg;
    for (const auto& n : needles) EXPECT_NE(msg.find(n), std::string::npos) << "'" << n << "' not in: " << msg;
    return;
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected d2gs::Error, got " << typeid(e).name() << ": " << e.what();
    return;
  }
  ADD_FAILURE() << "expected d2gs::Error, got no exception";
}

// ---- Gaussians: round trips -----------------------------------------------------------------------

TEST(PlyGaussians, RoundTripIsBitExactForEveryDegree) {
  const auto dir = scratch_dir();
  for (int degree = 0; degree <= 3; ++degree) {
    const auto model = random_model(257, degree, 1234u + static_cast<std::uint32_t>(degree));
    const auto path = dir / fmt::format("model_sh{}.ply", degree);
    write_gaussians_ply(path, model);
    const auto back = read_gaussians_ply(path);
    SCOPED_TRACE(degree);
    expect_bit_identical(model, back);
    // Writing what was read gives the same bytes again.
    write_gaussians_ply(dir / "again.ply", back);
    EXPECT_EQ(read_file(path), read_file(dir / "again.ply"));
  }
}

TEST(PlyGaussians, RoundTripEmptyModel) {
  const auto path = scratch_dir() / "empty.ply";
  Gaussians g;
  g.resize(0, 2);
  write_gaussians_ply(path, g);
  const auto back = read_gaussians_ply(path);
  EXPECT_EQ(back.size(), 0u);
  EXPECT_EQ(back.sh_degree, 2);
}

TEST(PlyGaussians, WriterUsesViewerLayout) {
  const auto dir = scratch_dir();
  const int expected_rest[] = {0, 9, 24, 45};
  for (int degree = 0; degree <= 3; ++degree) {
    const auto path = dir / "m.ply";
    write_gaussians_ply(path, random_model(5, degree, 7));
    const std::string bytes = read_file(path);
    const auto end = bytes.find("end_header\n");
    ASSERT_NE(end, std::string::npos);
    std::string expected = "ply\nformat binary_little_endian 1.0\nelement vertex 5\n";
    std::vector<std::string> names = {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"};
    for (int j = 0; j < expected_rest[degree]; ++j) names.push_back("f_rest_" + std::to_string(j));
    for (const char* s : {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"}) names.push_back(s);
    for (const auto& n : names) expected += "property float " + n + "\n";
    EXPECT_EQ(bytes.substr(0, end), expected);
    EXPECT_EQ(bytes.size(), end + 11 + 5 * names.size() * 4);
    // Normals are written as zeros.
    float nx = 1;
    std::memcpy(&nx, bytes.data() + end + 11 + 3 * 4, 4);
    EXPECT_EQ(bits(nx), 0u);
  }
}

// ---- Gaussians: golden files of an independent writer (tools/make_ply_fixture.py) -----------------

TEST(PlyGaussians, GoldenFixturesReadToTheirModel) {
  const std::pair<const char*, std::pair<std::size_t, int>> cases[] = {
      {"gaussians_sh0.ply", {2, 0}}, {"gaussians_sh1.ply", {3, 1}}, {"gaussians_sh3.ply", {2, 3}}};
  for (const auto& [name, shape] : cases) {
    SCOPED_TRACE(name);
    expect_bit_identical(read_gaussians_ply(fixture(name)), fixture_model(shape.first, shape.second));
  }
}

TEST(PlyGaussians, WritingTheFixtureModelGivesTheGoldenBytes) {
  const auto dir = scratch_dir();
  const std::pair<const char*, std::pair<std::size_t, int>> cases[] = {
      {"gaussians_sh0.ply", {2, 0}}, {"gaussians_sh1.ply", {3, 1}}, {"gaussians_sh3.ply", {2, 3}}};
  for (const auto& [name, shape] : cases) {
    SCOPED_TRACE(name);
    write_gaussians_ply(dir / name, fixture_model(shape.first, shape.second));
    const std::string golden = read_file(fixture(name));
    ASSERT_GT(golden.size(), 400u);
    EXPECT_EQ(read_file(dir / name), golden);
  }
}

// ---- Gaussians: other writers' files ---------------------------------------------------------------

TEST(PlyGaussians, PropertiesMatchedByNameInAnyOrder) {
  const auto model = random_model(31, 3, 99);
  auto cols = model_columns(model);
  std::mt19937 rng(5);
  for (int trial = 0; trial < 5; ++trial) {
    std::shuffle(cols.begin(), cols.end(), rng);
    const auto bytes = make_ply("binary_little_endian", {vertex_from_columns(cols)});
    expect_bit_identical(parse_gaussians_ply(bytes, "shuffled.ply"), model);
  }
}

TEST(PlyGaussians, MissingNormalsAndExtraPropertiesAccepted) {
  const auto model = random_model(9, 1, 3);
  auto cols = model_columns(model, /*normals=*/false);
  cols.insert(cols.begin() + 2, {"confidence", std::vector<double>(9, 0.5)});
  cols.push_back({"filter_3D", std::vector<double>(9, -1.0)});
  auto vertex = vertex_from_columns(cols);
  vertex.props[2].type = "double";  // an extra property of another size must not shift the others
  for (auto& row : vertex.rows) row[2] = {0.25};
  expect_bit_identical(parse_gaussians_ply(make_ply("binary_little_endian", {vertex}), "extra.ply"), model);
}

TEST(PlyGaussians, AsciiFile) {
  const auto model = random_model(12, 2, 11);  // fmt prints the shortest round-tripping text
  const auto bytes = make_ply("ascii", {vertex_from_columns(model_columns(model))});
  expect_bit_identical(parse_gaussians_ply(bytes, "ascii.ply"), model);
}

TEST(PlyGaussians, BigEndianFile) {
  const auto model = random_model(12, 3, 12);
  const auto bytes = make_ply("binary_big_endian", {vertex_from_columns(model_columns(model))});
  expect_bit_identical(parse_gaussians_ply(bytes, "be.ply"), model);
}

TEST(PlyGaussians, DoubleAndIntegerPropertyTypesConvertToFloat) {
  const auto exact = integer_model(6, 1);
  for (const char* type : {"double", "float64", "float32", "uchar", "uint8", "char", "int8", "short", "int16",
                           "ushort", "uint16", "int", "int32", "uint", "uint32"}) {
    for (const char* format : {"binary_little_endian", "binary_big_endian", "ascii"}) {
      SCOPED_TRACE(std::string(type) + " " + format);
      const auto bytes = make_ply(format, {vertex_from_columns(model_columns(exact), type)});
      expect_bit_identical(parse_gaussians_ply(bytes, "typed.ply"), exact);
    }
  }
  // Doubles are rounded to the nearest float.
  const auto model = random_model(4, 0, 8);
  auto cols = model_columns(model);
  for (auto& c : cols)
    for (auto& v : c.second) v = static_cast<double>(static_cast<float>(v)) * (1.0 + 1e-12);
  const auto back = parse_gaussians_ply(make_ply("binary_little_endian", {vertex_from_columns(cols, "double")}), "d.ply");
  for (std::size_t i = 0; i < model.means.size(); ++i) {
    const float expected = static_cast<float>(static_cast<double>(model.means[i]) * (1.0 + 1e-12));
    EXPECT_EQ(bits(back.means[i]), bits(expected));
  }
}

TEST(PlyGaussians, OtherElementsAndListsSkipped) {
  const auto model = random_model(7, 1, 21);
  const Element faces{"face", {{"vertex_indices", "int", "uchar"}, {"flags", "uchar", ""}},
                      {{{0, 1, 2}, {3}}, {{2, 3, 4, 5}, {0}}, {{}, {9}}}, {}};
  const Element edges{"edge", {{"a", "int", ""}, {"b", "int", ""}, {"ends", "double", "uint"}}, {{{1}, {2}, {0.5, 1.5}}}, {}};
  const Element empty_props{"nothing", {}, {}, "1000000000000"};  // no properties: occupies no bytes
  auto vertex = vertex_from_columns(model_columns(model));
  vertex.props.push_back({"neighbours", "int", "ushort"});  // a list inside the vertex element too
  for (std::size_t i = 0; i < vertex.rows.size(); ++i) vertex.rows[i].push_back(std::vector<double>(i, 3.0));
  for (const char* format : {"binary_little_endian", "binary_big_endian", "ascii"}) {
    SCOPED_TRACE(format);
    expect_bit_identical(parse_gaussians_ply(make_ply(format, {faces, empty_props, vertex, edges}), "lists.ply"), model);
    expect_bit_identical(parse_gaussians_ply(make_ply(format, {vertex, faces}), "lists.ply"), model);
  }
}

TEST(PlyGaussians, CrLfHeaderCommentsAndObjInfo) {
  const auto model = random_model(3, 0, 4);
  const auto bytes = make_ply("binary_little_endian", {vertex_from_columns(model_columns(model))}, "\r\n",
                              "obj_info made on windows\r\ncomment   spaced\t\tcomment\r\n\r\n");
  expect_bit_identical(parse_gaussians_ply(bytes, "crlf.ply"), model);
}

// ---- Gaussians: bad inputs -------------------------------------------------------------------------

TEST(PlyGaussians, MissingRequiredPropertyNamesFileAndProperty) {
  const auto model = random_model(2, 1, 5);
  const auto all = model_columns(model);
  const auto dir = scratch_dir();
  for (const char* required : {"x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
                               "rot_0", "rot_1", "rot_2", "rot_3", "f_rest_4"}) {
    auto cols = all;
    cols.erase(std::find_if(cols.begin(), cols.end(), [&](const auto& c) { return c.first == required; }));
    if (std::string(required) == "f_rest_4") cols.push_back({"f_rest_99", std::vector<double>(2, 0.0)});  // keep 9
    const auto path = dir / fmt::format("no_{}.ply", required);
    write_file_atomic(path, make_ply("binary_little_endian", {vertex_from_columns(cols)}));
    SCOPED_TRACE(required);
    expect_error([&] { read_gaussians_ply(path); }, {path.string(), fmt::format("'{}'", required), "missing"});
  }
}

TEST(PlyGaussians, UnsupportedShCoefficientCountRejected) {
  const auto base = model_columns(random_model(2, 0, 5));
  for (int extra : {1, 3, 8, 10, 23, 46}) {
    auto cols = base;
    for (int j = 0; j < extra; ++j) cols.push_back({fmt::format("f_rest_{}", j), {0.0, 0.0}});
    SCOPED_TRACE(extra);
    expect_error([&] { parse_gaussians_ply(make_ply("binary_little_endian", {vertex_from_columns(cols)}), "sh.ply"); },
                 {"sh.ply", fmt::format("{} f_rest", extra), "0, 9, 24 or 45"});
  }
}

TEST(PlyGaussians, TruncatedDataRejectedAtEveryLength) {
  Gaussians g = random_model(3, 1, 77);
  const auto path = scratch_dir() / "t.ply";
  write_gaussians_ply(path, g);
  const std::string bytes = read_file(path);
  const std::string ascii = make_ply("ascii", {vertex_from_columns(model_columns(g))});
  // Every prefix of the binary file fails. Ascii: every prefix that loses at least one whole token
  // (a cut inside the last token still leaves a complete file with a shorter last number).
  const std::size_t last_content = ascii.find_last_not_of(" \n");
  const std::size_t last_token = ascii.find_last_of(" \n", last_content) + 1;
  const std::pair<const std::string*, std::size_t> files[] = {{&bytes, bytes.size()}, {&ascii, last_token}};
  for (const auto& [full, limit] : files) {
    for (std::size_t len = 0; len < limit; ++len) {
      const std::string_view prefix(full->data(), len);
      try {
        parse_gaussians_ply(prefix, "cut.ply");
        ADD_FAILURE() << "prefix of " << len << " bytes was accepted";
      } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("cut.ply"), std::string::npos);
        EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos);
      }
    }
  }
  expect_error([&] { parse_gaussians_ply(std::string_view(bytes.data(), bytes.size() - 1), "cut.ply"); },
               {"cut.ply", "truncated"});
}

TEST(PlyGaussians, AbsurdVertexCountsRejectedWithoutAllocating) {
  const auto model = random_model(2, 3, 1);
  for (const char* count : {"1000000000000000000", "18446744073709551615", "4611686018427387904", "3"}) {
    for (const char* format : {"binary_little_endian", "ascii"}) {
      auto vertex = vertex_from_columns(model_columns(model));
      vertex.declared_count = count;
      SCOPED_TRACE(std::string(count) + " " + format);
      expect_error([&] { parse_gaussians_ply(make_ply(format, {vertex}), "big.ply"); }, {"big.ply", "truncated"});
    }
  }
  for (const char* count : {"18446744073709551616", "-1", "1e6", "12abc", "0x10", "+2"}) {
    auto vertex = vertex_from_columns(model_columns(model));
    vertex.declared_count = count;
    SCOPED_TRACE(count);
    expect_error([&] { parse_gaussians_ply(make_ply("binary_little_endian", {vertex}), "count.ply"); }, {"count.ply"});
  }
  // A huge element before the vertex element.
  Element faces{"face", {{"vertex_indices", "int", "uchar"}}, {}, "1000000000000000"};
  expect_error([&] { parse_gaussians_ply(make_ply("binary_little_endian", {faces, vertex_from_columns(model_columns(model))}), "f.ply"); },
               {"f.ply", "truncated", "'face'"});
  // A list whose length runs past the end.
  Element long_list{"face", {{"vertex_indices", "int", "uint"}}, {{{1, 2, 3}}}, {}};
  std::string bytes = make_ply("binary_little_endian", {long_list, vertex_from_columns(model_columns(model))});
  const auto data = bytes.find("end_header\n") + 11;
  const std::uint32_t huge = 0xfffffff0u;
  std::memcpy(bytes.data() + data, &huge, 4);
  expect_error([&] { parse_gaussians_ply(bytes, "l.ply"); }, {"l.ply", "truncated", "vertex_indices"});
  // Negative list length.
  Element neg{"face", {{"vertex_indices", "int", "int"}}, {{{1}}}, {}};
  bytes = make_ply("binary_little_endian", {neg, vertex_from_columns(model_columns(model))});
  const std::int32_t minus = -5;
  std::memcpy(bytes.data() + bytes.find("end_header\n") + 11, &minus, 4);
  expect_error([&] { parse_gaussians_ply(bytes, "n.ply"); }, {"n.ply", "negative"});
}

// The data ends where the last declared element's does: bytes after it (trailing bytes, or a vertex
// count lower than the data) and elements whose data is absent are errors, in every format.
TEST(PlyGaussians, DataMustEndExactlyWithTheLastElement) {
  const auto model = random_model(3, 1, 31);
  const auto dir = scratch_dir();
  const auto path = dir / "m.ply";
  write_gaussians_ply(path, model);
  const std::string good = read_file(path);
  for (const std::size_t extra : {1, 16, 1000}) {
    write_file_atomic(path, good + std::string(extra, '\0'));
    SCOPED_TRACE(extra);
    expect_error([&] { read_gaussians_ply(path); },
                 {path.string(), fmt::format("{} unexpected bytes after the last item of element 'vertex'", extra),
                  "trailing bytes"});
  }
  // A header that declares fewer vertices than the data holds: the same case, not a smaller model.
  std::string fewer = good;
  fewer.replace(fewer.find("element vertex 3"), 16, "element vertex 2");
  expect_error([&] { parse_gaussians_ply(fewer, "fewer.ply"); },
               {"fewer.ply", "unexpected bytes after the last item of element 'vertex'", "fewer items"});
  std::string none = good;
  none.replace(none.find("element vertex 3"), 16, "element vertex 0");
  expect_error([&] { parse_gaussians_ply(none, "none.ply"); }, {"none.ply", "unexpected bytes"});

  const Element absent{"face", {{"vertex_indices", "int", "uchar"}}, {}, "5"};  // declared, no data
  Element partial{"face", {{"vertex_indices", "int", "uchar"}}, {{{0, 1, 2}}, {{1, 2, 0}}}, "5"};
  for (const char* format : {"binary_little_endian", "binary_big_endian", "ascii"}) {
    SCOPED_TRACE(format);
    const auto vertex = vertex_from_columns(model_columns(model));
    expect_error([&] { parse_gaussians_ply(make_ply(format, {vertex, absent}), "face.ply"); },
                 {"face.ply", "truncated", "'face'"});
    expect_error([&] { parse_gaussians_ply(make_ply(format, {vertex, partial}), "face.ply"); },
                 {"face.ply", "truncated", "'face'"});
    Element fewer_vertices = vertex;
    fewer_vertices.declared_count = "2";
    expect_error([&] { parse_gaussians_ply(make_ply(format, {fewer_vertices}), "fewer.ply"); },
                 {"fewer.ply", "after the last item of element 'vertex'"});
    // The complete file still reads, with the face element after the vertices.
    partial.declared_count = "";
    expect_bit_identical(parse_gaussians_ply(make_ply(format, {vertex, partial}), "face.ply"), model);
    partial.declared_count = "5";
  }
  // Ascii: white space after the last item is fine (a final newline, blank lines), another line is not.
  const std::string ascii = make_ply("ascii", {vertex_from_columns(model_columns(model))});
  expect_bit_identical(parse_gaussians_ply(ascii + "\n  \r\n\t\n", "a.ply"), model);
  const auto lines = std::count(ascii.begin(), ascii.end(), '\n');
  expect_error([&] { parse_gaussians_ply(ascii + "\n1 2 3\n", "a.ply"); },
               {"a.ply", fmt::format("line {}: unexpected data '1 2 3' after the last item of element 'vertex'", lines + 2)});
  expect_error([&] { parse_gaussians_ply(ascii + std::string("\xff\0", 2), "a.ply"); }, {"a.ply", "'\\xff\\x00'"});
}

TEST(PlyGaussians, NanRejectedNamingFilePropertyAndVertex) {
  auto model = random_model(6, 2, 9);
  auto cols = model_columns(model);
  const auto set = [&](const std::string& name, std::size_t vertex, double v) {
    auto c = cols;
    for (auto& col : c)
      if (col.first == name) col.second[vertex] = v;
    return c;
  };
  const auto dir = scratch_dir();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::tuple<const char*, std::size_t, const char*> cases[] = {
      {"x", 0, "binary_little_endian"}, {"f_rest_17", 4, "binary_big_endian"}, {"rot_3", 5, "ascii"},
      {"opacity", 3, "binary_little_endian"}};
  for (const auto& [name, vertex, format] : cases) {
    const auto path = dir / fmt::format("nan_{}.ply", name);
    write_file_atomic(path, make_ply(format, {vertex_from_columns(set(name, vertex, nan))}));
    SCOPED_TRACE(name);
    expect_error([&] { read_gaussians_ply(path); }, {path.string(), fmt::format("'{}'", name), fmt::format("vertex {}", vertex), "NaN"});
  }
  // Infinity and doubles beyond the float range are rejected too.
  expect_error([&] { parse_gaussians_ply(make_ply("binary_little_endian", {vertex_from_columns(set("scale_1", 2, INFINITY))}), "i.ply"); },
               {"i.ply", "'scale_1'", "vertex 2", "infinite"});
  expect_error([&] { parse_gaussians_ply(make_ply("binary_little_endian", {vertex_from_columns(set("y", 1, 1e300), "double")}), "d.ply"); },
               {"d.ply", "'y'", "vertex 1", "out of float range"});
  expect_error([&] { parse_gaussians_ply(make_ply("ascii", {vertex_from_columns(set("z", 1, 1e300), "float32")}), "a.ply"); },
               {"a.ply", "'z'", "vertex 1"});
  // The float range ends where IEEE rounding overflows: half an ulp above FLT_MAX.
  const auto one = [&](double v) {
    return parse_gaussians_ply(make_ply("binary_little_endian", {vertex_from_columns(set("x", 0, v), "double")}), "e.ply").means[0];
  };
  EXPECT_EQ(one(0x1.fffffefffffffp127), kMax);
  EXPECT_EQ(one(-0x1.fffffefffffffp127), -kMax);
  expect_error([&] { one(0x1.ffffffp127); }, {"e.ply", "out of float range"});
  EXPECT_EQ(bits(one(0x1p-150 * 1.5)), bits(std::numeric_limits<float>::denorm_min()));
  EXPECT_EQ(bits(one(-0x1p-151)), bits(-0.0f));
}

TEST(PlyGaussians, MalformedHeadersRejected) {
  const std::string good_tail = "element vertex 0\nproperty float x\nend_header\n";
  const std::pair<std::string, std::string> cases[] = {
      {"", "not a PLY file"},
      {"PLY\n", "not a PLY file"},
      {"plyx\n", "not a PLY file"},
      {"\x89PNG\r\n\x1a\n", "not a PLY file"},
      {"ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\n", "end_header"},
      {"ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nend_header", "end_header"},
      {"ply\n" + good_tail, "no format"},
      {"ply\nformat binary_middle_endian 1.0\n" + good_tail, "unknown format"},
      {"ply\nformat ascii 2.0\n" + good_tail, "version"},
      {"ply\nformat ascii\n" + good_tail, "malformed format"},
      {"ply\nformat ascii 1.0\nformat ascii 1.0\n" + good_tail, "second 'format'"},
      {"ply\nformat ascii 1.0\nproperty float x\n" + good_tail, "property before any element"},
      {"ply\nformat ascii 1.0\nelement vertex 0\nproperty half x\nend_header\n", "unknown property type 'half'"},
      {"ply\nformat ascii 1.0\nelement vertex 0\nproperty float\nend_header\n", "malformed property"},
      {"ply\nformat ascii 1.0\nelement vertex 0\nproperty list uchar x\nend_header\n", "malformed list"},
      {"ply\nformat ascii 1.0\nelement vertex 0\nproperty list float int x\nend_header\n", "count type"},
      {"ply\nformat ascii 1.0\nelement vertex 0\nproperty list uchar blob x\nend_header\n", "unknown property type"},
      {"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty double x\nend_header\n", "duplicate property 'x'"},
      {"ply\nformat ascii 1.0\nelement vertex 0\nelement vertex 0\nend_header\n", "duplicate element"},
      {"ply\nformat ascii 1.0\nelement vertex\nend_header\n", "malformed element"},
      {"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nwhatever 3\nend_header\n", "unexpected 'whatever'"},
      {"ply\nformat ascii 1.0\nelement face 0\nend_header\n", "no 'vertex' element"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar float x\nend_header\n1 1.0\n", "is a list"},
  };
  for (const auto& [bytes, needle] : cases) {
    SCOPED_TRACE(bytes);
    expect_error([&] { parse_gaussians_ply(bytes, "h.ply"); }, {"h.ply", needle});
    expect_error([&] { parse_point_cloud_ply(bytes, "h.ply"); }, {"h.ply"});
  }
}

TEST(PlyGaussians, MalformedAsciiValuesRejected) {
  const auto model = integer_model(2, 0);
  const std::string good = make_ply("ascii", {vertex_from_columns(model_columns(model))});
  const auto header_end = good.find("end_header\n") + 11;
  const std::string head = good.substr(0, header_end);
  const std::string body = good.substr(header_end);
  for (const char* bad : {"abc", "1.0.0", "0x10", "--1", "1,5", "\x01"}) {
    std::string b = body;
    b.replace(0, b.find(' '), bad);
    SCOPED_TRACE(bad);
    expect_error([&] { parse_gaussians_ply(head + b, "a.ply"); }, {"a.ply", "'x'", "item 0", "not a valid number"});
  }
  // Integer properties: fractional text and out-of-range values.
  const std::string int_head = make_ply("ascii", {vertex_from_columns(model_columns(model), "uchar")});
  const auto ih = int_head.find("end_header\n") + 11;
  for (const auto& [bad, why] : {std::pair<const char*, const char*>{"1.5", "not a valid number"}, {"256", "out of range"}, {"-1", "out of range"}}) {
    std::string b = int_head.substr(ih);
    b.replace(0, b.find(' '), bad);
    expect_error([&] { parse_gaussians_ply(int_head.substr(0, ih) + b, "u.ply"); }, {"u.ply", why});
  }
  // Leading '+' and exponent forms are accepted.
  std::string b = body;
  b.replace(0, b.find(' '), "+0.0e0");
  EXPECT_NO_THROW(parse_gaussians_ply(head + b, "ok.ply"));
}

TEST(PlyGaussians, WriterRejectsNonFiniteAndInvalidModelsAndLeavesNoFile) {
  const auto dir = scratch_dir();
  auto model = random_model(4, 1, 2);
  model.sh_rest[7] = std::numeric_limits<float>::quiet_NaN();
  expect_error([&] { write_gaussians_ply(dir / "nan.ply", model); }, {"nan.ply", "Gaussian 0", "f_rest_", "NaN"});
  model = random_model(4, 1, 2);
  model.quats[4 * 3 + 1] = -INFINITY;
  expect_error([&] { write_gaussians_ply(dir / "inf.ply", model); }, {"inf.ply", "Gaussian 3", "'rot_1'", "infinite"});
  model = random_model(4, 1, 2);
  model.sh_rest.pop_back();
  expect_error([&] { write_gaussians_ply(dir / "bad.ply", model); }, {"bad.ply", "sh_rest"});
  EXPECT_TRUE(fs::is_empty(dir)) << "a failed write left files behind";
}

TEST(PlyGaussians, WriterReportsTheFRestIndexOfTheFileLayout) {
  // sh_rest memory index (k=1, c=2) of Gaussian 0 is file property f_rest_(2*3+1) = f_rest_7 at degree 1.
  auto model = random_model(2, 1, 3);
  model.sh_rest[1 * 3 + 2] = std::numeric_limits<float>::quiet_NaN();
  expect_error([&] { write_gaussians_ply(scratch_dir() / "m.ply", model); }, {"'f_rest_7'"});
}

TEST(PlyGaussians, OverwriteIsAtomicAndMissingFileNamed) {
  const auto dir = scratch_dir();
  const auto path = dir / "model.ply";
  write_gaussians_ply(path, random_model(10, 0, 1));
  const auto second = random_model(3, 3, 2);
  write_gaussians_ply(path, second);
  expect_bit_identical(read_gaussians_ply(path), second);
  EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator()), 1);
  expect_error([&] { read_gaussians_ply(dir / "missing.ply"); }, {(dir / "missing.ply").string(), "not found"});
  expect_error([&] { read_point_cloud_ply(dir / "missing.ply"); }, {(dir / "missing.ply").string(), "not found"});
}

// ---- point clouds ----------------------------------------------------------------------------------

PointCloud fixture_cloud() {
  PointCloud c;
  for (std::size_t i = 0; i < 4; ++i) {
    c.positions.emplace_back(fixture_value(i, 0, 0), fixture_value(i, 0, 1), fixture_value(i, 0, 2));
    c.colors.emplace_back((i * 70) % 256, (i * 70 + 30) % 256, (i * 70 + 60) % 256);
  }
  return c;
}

void expect_same_cloud(const PointCloud& a, const PointCloud& b) {
  ASSERT_EQ(a.size(), b.size());
  ASSERT_EQ(a.colors.size(), b.colors.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    for (int j = 0; j < 3; ++j) ASSERT_EQ(bits(a.positions[i][j]), bits(b.positions[i][j])) << i << "," << j;
    ASSERT_EQ(a.colors[i], b.colors[i]) << i;
  }
}

TEST(PlyPointCloud, GoldenFixtureReadAndWritten) {
  expect_same_cloud(read_point_cloud_ply(fixture("points.ply")), fixture_cloud());
  const auto path = scratch_dir() / "points.ply";
  write_point_cloud_ply(path, fixture_cloud());
  EXPECT_EQ(read_file(path), read_file(fixture("points.ply")));
}

TEST(PlyPointCloud, RoundTrip) {
  PointCloud c;
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-100.0f, 100.0f);
  for (int i = 0; i < 1000; ++i) {
    c.positions.emplace_back(u(rng), u(rng), u(rng));
    c.colors.emplace_back(rng() % 256, rng() % 256, rng() % 256);
  }
  const auto path = scratch_dir() / "c.ply";
  write_point_cloud_ply(path, c);
  expect_same_cloud(read_point_cloud_ply(path), c);
  PointCloud empty;
  write_point_cloud_ply(path, empty);
  EXPECT_TRUE(read_point_cloud_ply(path).empty());
}

TEST(PlyPointCloud, AnyOrderFloatColoursAndFormats) {
  const PointCloud c = fixture_cloud();
  std::vector<std::pair<std::string, std::vector<double>>> cols(6);
  for (int j = 0; j < 3; ++j) cols[static_cast<std::size_t>(j)].first = std::string(1, "xyz"[j]);
  cols[3].first = "blue";
  cols[4].first = "red";
  cols[5].first = "green";
  for (std::size_t i = 0; i < c.size(); ++i) {
    for (int j = 0; j < 3; ++j) cols[static_cast<std::size_t>(j)].second.push_back(c.positions[i][j]);
    cols[3].second.push_back(c.colors[i].z / 255.0);
    cols[4].second.push_back(c.colors[i].x / 255.0);
    cols[5].second.push_back(c.colors[i].y / 255.0);
  }
  for (const char* format : {"binary_little_endian", "binary_big_endian", "ascii"}) {
    auto v = vertex_from_columns(cols);
    for (std::size_t p = 3; p < 6; ++p) v.props[p].type = "double";
    std::rotate(v.props.begin(), v.props.begin() + 2, v.props.end());
    for (auto& row : v.rows) std::rotate(row.begin(), row.begin() + 2, row.end());
    SCOPED_TRACE(format);
    expect_same_cloud(parse_point_cloud_ply(make_ply(format, {v}), "f.ply"), c);
  }
  // uchar and ushort colours, extra properties, a face element.
  auto v = vertex_from_columns(cols);
  for (std::size_t p = 3; p < 6; ++p) {
    v.props[p].type = "ushort";
    for (auto& row : v.rows) row[p][0] = std::round(row[p][0] * 255.0) * 257.0;
  }
  const Element faces{"face", {{"vertex_indices", "int", "uchar"}}, {{{0, 1, 2}}}, {}};
  expect_same_cloud(parse_point_cloud_ply(make_ply("binary_little_endian", {v, faces}), "u.ply"), c);
}

TEST(PlyPointCloud, MissingColoursAreGreyPartialColoursRejected) {
  const PointCloud c = fixture_cloud();
  std::vector<std::pair<std::string, std::vector<double>>> cols(3);
  for (int j = 0; j < 3; ++j) {
    cols[static_cast<std::size_t>(j)].first = std::string(1, "xyz"[j]);
    for (std::size_t i = 0; i < c.size(); ++i) cols[static_cast<std::size_t>(j)].second.push_back(c.positions[i][j]);
  }
  const auto cloud = parse_point_cloud_ply(make_ply("binary_little_endian", {vertex_from_columns(cols)}), "g.ply");
  ASSERT_EQ(cloud.size(), 4u);
  for (const auto& col : cloud.colors) EXPECT_EQ(col, glm::u8vec3(128));
  // A Gaussian model read as a point cloud: its means.
  const auto model = fixture_model(3, 1);
  const auto as_points = read_point_cloud_ply(fixture("gaussians_sh1.ply"));
  ASSERT_EQ(as_points.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_EQ(bits(as_points.positions[i][j]), bits(model.means[i * 3 + static_cast<std::size_t>(j)]));
  cols.push_back({"red", {1, 2, 3, 4}});
  expect_error([&] { parse_point_cloud_ply(make_ply("binary_little_endian", {vertex_from_columns(cols, "uchar")}), "p.ply"); },
               {"p.ply", "colour"});
  cols.pop_back();
  cols.erase(cols.begin() + 1);
  expect_error([&] { parse_point_cloud_ply(make_ply("binary_little_endian", {vertex_from_columns(cols)}), "p.ply"); },
               {"p.ply", "'y'", "missing"});
}

TEST(PlyPointCloud, DataMustEndExactlyWithTheLastElement) {
  const auto dir = scratch_dir();
  write_point_cloud_ply(dir / "ok.ply", fixture_cloud());
  const std::string good = read_file(dir / "ok.ply");
  expect_same_cloud(parse_point_cloud_ply(good, "ok.ply"), fixture_cloud());
  expect_error([&] { parse_point_cloud_ply(good + std::string(16, 'x'), "t.ply"); },
               {"t.ply", "16 unexpected bytes after the last item of element 'vertex'"});
  std::string fewer = good;
  fewer.replace(fewer.find("vertex 4"), 8, "vertex 3");
  expect_error([&] { parse_point_cloud_ply(fewer, "fewer.ply"); }, {"fewer.ply", "27 unexpected bytes"});
  // An element declared after the vertices (fused.ply with faces) whose data is absent.
  std::string faces = good;
  faces.insert(faces.find("end_header"), "element face 5\nproperty list uchar int vertex_indices\n");
  expect_error([&] { parse_point_cloud_ply(faces, "f.ply"); }, {"f.ply", "truncated", "'face'"});
  const std::string ascii = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
                            "end_header\n1 2 3\n4 5 6\n";
  EXPECT_EQ(parse_point_cloud_ply(ascii, "a.ply").size(), 2u);
  expect_error([&] { parse_point_cloud_ply(ascii + "7 8 9\n", "a.ply"); }, {"a.ply", "line 10", "'7 8 9'"});
  expect_error([&] { parse_point_cloud_ply(ascii.substr(0, ascii.size() - 6), "a.ply"); }, {"a.ply", "truncated"});
}

// What the field writes keeps loading: every .ply of the shared data (COLMAP's fused.ply of the
// published pipeline: binary, normals, uchar colours), and the writers' own layouts above.
TEST(PlyPointCloud, SharedDataCloudsLoad) {
  const auto fused = test::shared_data() / "published_init" / "fern" / "3_views_fused.ply";
  ASSERT_TRUE(fs::is_regular_file(fused)) << fused;
  EXPECT_EQ(read_point_cloud_ply(fused).size(), 17903u);
  int files = 0;
  for (const auto& entry : fs::recursive_directory_iterator(test::shared_data()))
    if (entry.is_regular_file() && entry.path().extension() == ".ply") {
      SCOPED_TRACE(entry.path().string());
      EXPECT_NO_THROW(read_point_cloud_ply(entry.path()));
      ++files;
    }
  EXPECT_GE(files, 1);
}

TEST(PlyPointCloud, BadInputsRejected) {
  const auto dir = scratch_dir();
  write_point_cloud_ply(dir / "ok.ply", fixture_cloud());
  const std::string bytes = read_file(dir / "ok.ply");
  for (std::size_t len = 0; len + 1 < bytes.size(); ++len)
    EXPECT_THROW(parse_point_cloud_ply(std::string_view(bytes.data(), len), "cut.ply"), Error) << len;
  std::string nan_file = bytes;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(nan_file.data() + nan_file.find("end_header\n") + 11 + 27 * 2 + 4, &nan, 4);
  expect_error([&] { parse_point_cloud_ply(nan_file, "nan.ply"); }, {"nan.ply", "vertex 2", "'y'", "NaN"});
  std::string big = bytes;
  big.replace(big.find("vertex 4"), 8, "vertex 99999999999");
  expect_error([&] { parse_point_cloud_ply(big, "big.ply"); }, {"big.ply", "truncated"});
  PointCloud mismatched = fixture_cloud();
  mismatched.colors.pop_back();
  expect_error([&] { write_point_cloud_ply(dir / "m.ply", mismatched); }, {"m.ply", "colours"});
  PointCloud with_nan = fixture_cloud();
  with_nan.positions[1].z = nan;
  expect_error([&] { write_point_cloud_ply(dir / "n.ply", with_nan); }, {"n.ply", "point 1", "NaN"});
}

}  // namespace
}  // namespace d2gs
