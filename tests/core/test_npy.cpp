#include <gtest/gtest.h>

#include <cstring>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/npy.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {

std::string npy_bytes(const std::string& dict, const std::string& data) {
  std::string header = dict;
  const std::size_t total = 10 + header.size() + 1;
  header.append((64 - total % 64) % 64, ' ');
  header.push_back('\n');
  std::string out("\x93NUMPY\x01\x00", 8);
  out.push_back(static_cast<char>(header.size() & 0xff));
  out.push_back(static_cast<char>(header.size() >> 8));
  return out + header + data;
}

TEST(Npy, ReadsFernPosesBoundsWrittenByNumpy) {
  const auto a = read_npy(test::shared_data() / "nerf_llff_data/fern/poses_bounds.npy");
  ASSERT_EQ(a.shape, (std::vector<std::size_t>{20, 17}));
  // Column 4 of the 3x5 matrix is (H, W, f) at full resolution (SOURCES.md).
  EXPECT_DOUBLE_EQ(a.values[4], 3024.0);
  EXPECT_DOUBLE_EQ(a.values[9], 4032.0);
  EXPECT_NEAR(a.values[14], 3260.526, 1e-3);
}

TEST(Npy, RoundTripFloat32) {
  const auto dir = test::scratch_dir();
  const std::vector<float> v = {1.5f, -2.25f, 3.0f, 1e-30f, 7.0f, 8.0f};
  write_npy_f32(dir / "a.npy", {2, 3}, v);
  const auto a = read_npy(dir / "a.npy");
  ASSERT_EQ(a.shape, (std::vector<std::size_t>{2, 3}));
  for (std::size_t i = 0; i < v.size(); ++i) EXPECT_EQ(static_cast<float>(a.values[i]), v[i]);
}

TEST(Npy, RoundTripFloat64) {
  const auto dir = test::scratch_dir();
  const std::vector<double> v = {1.0 / 3.0, -1e300, 4e-320, 0.0};
  write_npy_f64(dir / "d.npy", {4}, v);
  const auto a = read_npy(dir / "d.npy");
  ASSERT_EQ(a.shape, (std::vector<std::size_t>{4}));
  EXPECT_EQ(a.values, v);
  EXPECT_THROW(write_npy_f64(dir / "e.npy", {3}, v), Error);
}

TEST(Npy, FortranOrderBecomesRowMajor) {
  // 2x3 array [[0,1,2],[3,4,5]] stored column-major: 0 3 1 4 2 5.
  const double col_major[] = {0, 3, 1, 4, 2, 5};
  std::string data(reinterpret_cast<const char*>(col_major), sizeof col_major);
  const auto a = parse_npy(npy_bytes("{'descr': '<f8', 'fortran_order': True, 'shape': (2, 3), }", data), "x.npy");
  for (int i = 0; i < 6; ++i) EXPECT_EQ(a.values[i], i);
}

TEST(Npy, BigEndianInt32) {
  const unsigned char be[] = {0, 0, 1, 0, 0xff, 0xff, 0xff, 0xfe};
  const auto a = parse_npy(npy_bytes("{'descr': '>i4', 'fortran_order': False, 'shape': (2,), }",
                                     std::string(reinterpret_cast<const char*>(be), sizeof be)),
                           "x.npy");
  EXPECT_EQ(a.values[0], 256);
  EXPECT_EQ(a.values[1], -2);
}

TEST(Npy, BadInputsNameTheFile) {
  const auto expect_error = [](const std::string& bytes, const std::string& fragment) {
    try {
      parse_npy(bytes, "bad.npy");
      ADD_FAILURE() << "no error for " << fragment;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("bad.npy"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  };
  expect_error("hello", "bad magic");
  const std::string good = npy_bytes("{'descr': '<f4', 'fortran_order': False, 'shape': (4,), }", std::string(16, '\0'));
  expect_error(good.substr(0, good.size() - 3), "truncated");
  expect_error(good.substr(0, 20), "truncated");
  expect_error(good + std::string(16, '\0'), "16 unexpected bytes after the .npy data");
  expect_error(good + "x", "1 unexpected bytes");
  EXPECT_EQ(parse_npy(good, "good.npy").values.size(), 4u);
  expect_error(npy_bytes("{'descr': '<c16', 'fortran_order': False, 'shape': (1,), }", std::string(16, '\0')),
               "not supported");
  expect_error(npy_bytes("{'fortran_order': False, 'shape': (1,), }", std::string(16, '\0')), "descr");
  expect_error(npy_bytes("{'descr': '<`i2', 'fortran_order': False, 'shape': (1,), }", std::string(16, '\0')),
               "not supported");  // found by fuzz_npy: a non-numeric width
  // Found by fuzz_npy (10-minute run, issue 21): a zero-width dtype with a huge shape passed the size check
  // (any count of 0-byte values fits) and then asked for 720 GB of doubles.
  expect_error(npy_bytes("{'descr': '|u0', 'fortran_order': False, 'shape': (89913560442812352,), }", ""),
               "not supported");
  expect_error(npy_bytes("{'descr': '<f2', 'fortran_order': False, 'shape': (2,), }", std::string(4, '\0')),
               "not supported");
  EXPECT_THROW(read_npy(test::scratch_dir() / "missing.npy"), Error);
}

}  // namespace
}  // namespace d2gs
