// LPIPS against an independent PyTorch/torchvision reference (tools/make_lpips_fixtures.py): width-reduced
// VGG16 and AlexNet with seeded weights from committed files, full-width nets with closed-form weights
// rebuilt here; AVGE; and clean errors on bad weights and images.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <limits>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/npy.hpp"
#include "d2gs/eval/evaluate.hpp"
#include "d2gs/eval/lpips.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {

std::filesystem::path fixtures() { return test::source_dir() / "tests/eval/fixtures/lpips"; }

Image load_npy_image(const std::filesystem::path& path) {
  const NpyArray a = read_npy(path);
  EXPECT_EQ(a.shape.size(), 3u);
  Image im(static_cast<int>(a.shape[1]), static_cast<int>(a.shape[0]), static_cast<int>(a.shape[2]));
  for (std::size_t i = 0; i < a.values.size(); ++i) im.pixels[i] = static_cast<float>(a.values[i]);
  return im;
}

std::pair<Image, Image> pair_images(const std::string& name) {
  return {load_npy_image(fixtures() / ("img_" + name + "_a.npy")), load_npy_image(fixtures() / ("img_" + name + "_b.npy"))};
}

// hash_uniform() of tools/make_lpips_fixtures.py: values in [-1, 1), exact in float32.
std::vector<double> hash_uniform(std::uint64_t stream, std::size_t count) {
  std::vector<double> out(count);
  for (std::size_t n = 0; n < count; ++n) {
    std::uint64_t x = (n + 1) * 0x9E3779B97F4A7C15ull + stream * 0xBF58476D1CE4E5B9ull;
    x ^= x >> 31;
    x *= 0x94D049BB133111EBull;
    x ^= x >> 29;
    out[n] = static_cast<double>(x >> 40) / static_cast<double>(1 << 24) * 2.0 - 1.0;
  }
  return out;
}

struct ConvShape {
  int index, in, out, kernel;
};

// hash_weights() of the generator for torchvision's full-width trunks.
TensorFile hash_weights(const std::vector<ConvShape>& convs, const std::vector<int>& taps) {
  TensorFile f;
  for (const auto& c : convs) {
    const std::size_t fan_in = static_cast<std::size_t>(c.in) * static_cast<std::size_t>(c.kernel * c.kernel);
    const auto u = hash_uniform(2 * static_cast<std::uint64_t>(c.index), static_cast<std::size_t>(c.out) * fan_in);
    Tensor w{{c.out, c.in, c.kernel, c.kernel}, std::vector<float>(u.size())};
    for (std::size_t i = 0; i < u.size(); ++i) w.values[i] = static_cast<float>(u[i] * std::sqrt(6.0 / static_cast<double>(fan_in)));
    const auto ub = hash_uniform(2 * static_cast<std::uint64_t>(c.index) + 1, static_cast<std::size_t>(c.out));
    Tensor b{{c.out}, std::vector<float>(ub.size())};
    for (std::size_t i = 0; i < ub.size(); ++i) b.values[i] = static_cast<float>(0.05 * ub[i]);
    f.tensors[fmt::format("features.{}.weight", c.index)] = std::move(w);
    f.tensors[fmt::format("features.{}.bias", c.index)] = std::move(b);
  }
  for (std::size_t k = 0; k < taps.size(); ++k) {
    const auto u = hash_uniform(1000 + k, static_cast<std::size_t>(taps[k]));
    Tensor l{{1, taps[k], 1, 1}, std::vector<float>(u.size())};
    for (std::size_t i = 0; i < u.size(); ++i) l.values[i] = static_cast<float>(0.05 * (u[i] + 1.0));
    f.tensors[fmt::format("lin{}.weight", k)] = std::move(l);
  }
  return f;
}

// torchvision vgg16().features and alexnet().features: (feature index, in, out, kernel) of each conv.
const std::vector<ConvShape> kVgg16 = {{0, 3, 64, 3},     {2, 64, 64, 3},    {5, 64, 128, 3},   {7, 128, 128, 3},
                                       {10, 128, 256, 3}, {12, 256, 256, 3}, {14, 256, 256, 3}, {17, 256, 512, 3},
                                       {19, 512, 512, 3}, {21, 512, 512, 3}, {24, 512, 512, 3}, {26, 512, 512, 3},
                                       {28, 512, 512, 3}};
const std::vector<ConvShape> kAlexnet = {{0, 3, 64, 11}, {3, 64, 192, 5}, {6, 192, 384, 3}, {8, 384, 256, 3}, {10, 256, 256, 3}};

Lpips net_for_case(const std::string& key) {
  if (key == "vgg16_hash") return Lpips(hash_weights(kVgg16, {64, 128, 256, 512, 512}), "vgg16_hash");
  if (key == "alexnet_hash") return Lpips(hash_weights(kAlexnet, {64, 192, 384, 256, 256}), "alexnet_hash");
  return Lpips::load(fixtures() / (key + ".safetensors"));
}

// float32 convolutions against a float64 reference: the agreement we state (docs/benchmarks.md).
constexpr double kRelTol = 1e-5;

void check_against_reference(const std::string& net_prefix) {
  const auto expected = nlohmann::json::parse(read_file(fixtures() / "expected.json"));
  int checked = 0;
  double worst = 0;
  for (const auto& c : expected["cases"]) {
    const std::string key = c["net"];
    if (key.rfind(net_prefix, 0) != 0) continue;
    const Lpips net = net_for_case(key);
    EXPECT_EQ(to_string(net.trunk()), c["trunk"].get<std::string>());
    const auto [a, b] = pair_images(c["pair"]);
    const auto range = parse_lpips_input_range(c["range"].get<std::string>(), "case");
    const LpipsDistance d = net.distance(a, b, range);
    const double want = c["lpips"];
    const double rel = std::abs(d.total - want) / want;
    worst = std::max(worst, rel);
    EXPECT_LT(rel, kRelTol) << key << " " << c["pair"] << " " << c["range"] << ": " << d.total << " vs " << want;
    for (std::size_t k = 0; k < 5; ++k) {
      const double wk = c["per_tap"][k];
      EXPECT_NEAR(d.per_tap[k], wk, kRelTol * want) << key << " tap " << k;
    }
    ++checked;
  }
  EXPECT_EQ(checked, 4);  // two image pairs × two input ranges
  std::printf("%s*: worst relative difference to torch float64 %.2e over %d cases\n", net_prefix.c_str(), worst, checked);
  ::testing::Test::RecordProperty("worst_rel_" + net_prefix, std::to_string(worst));
}

TEST(Lpips, MatchesTorchOnWidthReducedVgg16FromFile) { check_against_reference("vgg16_w8"); }
TEST(Lpips, MatchesTorchOnWidthReducedAlexnetFromFile) { check_against_reference("alexnet_w8"); }
TEST(Lpips, MatchesTorchOnFullWidthVgg16WithClosedFormWeights) { check_against_reference("vgg16_hash"); }
TEST(Lpips, MatchesTorchOnFullWidthAlexnetWithClosedFormWeights) { check_against_reference("alexnet_hash"); }

TEST(Lpips, ChannelCountsComeFromTheFile) {
  const Lpips vgg = Lpips::load(fixtures() / "vgg16_w8.safetensors");
  EXPECT_EQ(vgg.trunk(), LpipsTrunk::vgg16);
  EXPECT_EQ(vgg.tap_channels(), (std::array<int, 5>{8, 16, 32, 64, 64}));
  EXPECT_EQ(vgg.description(), "vgg16 (taps 8, 16, 32, 64, 64)");
  EXPECT_EQ(vgg.min_size(), 16);
  const Lpips alex = Lpips::load(fixtures() / "alexnet_w8.safetensors");
  EXPECT_EQ(alex.trunk(), LpipsTrunk::alexnet);
  EXPECT_EQ(alex.tap_channels(), (std::array<int, 5>{8, 24, 48, 32, 32}));
  const Lpips full(hash_weights(kVgg16, {64, 128, 256, 512, 512}), "x");
  EXPECT_EQ(full.tap_channels(), (std::array<int, 5>{64, 128, 256, 512, 512}));
}

TEST(Lpips, ZeroForIdenticalImagesSymmetricInItsArguments) {
  const Lpips net = Lpips::load(fixtures() / "vgg16_w8.safetensors");
  const auto [a, b] = pair_images("41x35");
  EXPECT_EQ(net.distance(a, a, LpipsInputRange::unit).total, 0.0);
  const double ab = net.distance(a, b, LpipsInputRange::symmetric).total;
  const double ba = net.distance(b, a, LpipsInputRange::symmetric).total;
  EXPECT_GT(ab, 0.0);
  EXPECT_NEAR(ab, ba, 1e-12 * ab);
}

TEST(Lpips, BandingAndThreadingModeGiveTheSameDistance) {
  Lpips net(hash_weights(kVgg16, {64, 128, 256, 512, 512}), "x");
  const auto [a, b] = pair_images("64x48");
  const double reference = net.distance(a, b, LpipsInputRange::unit).total;
  net.set_im2col_floats(1);  // one output row per GEMM, shared among the threads
  EXPECT_NEAR(net.distance(a, b, LpipsInputRange::unit).total, reference, 1e-6 * reference);
  net.set_parallel_bands(false);  // rows in turn, GEMMs threaded by OpenBLAS
  EXPECT_NEAR(net.distance(a, b, LpipsInputRange::unit).total, reference, 1e-6 * reference);
  net.set_im2col_floats(std::size_t{1} << 22);
  EXPECT_NEAR(net.distance(a, b, LpipsInputRange::unit).total, reference, 1e-6 * reference);
}

std::string error_of(const TensorFile& f) {
  try {
    Lpips net(f, "w.safetensors");
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(Lpips, BadWeightsGiveOneLineErrorsNamingTheFile) {
  const TensorFile good = read_safetensors(fixtures() / "vgg16_w8.safetensors");
  EXPECT_EQ(error_of(good), "");
  struct Case {
    std::function<void(TensorFile&)> damage;
    std::string expected;
  };
  const std::vector<Case> cases = {
      {[](TensorFile& f) { f.tensors.erase("features.12.bias"); }, "missing tensor 'features.12.bias'"},
      {[](TensorFile& f) { f.tensors.erase("lin3.weight"); }, "missing tensor 'lin3.weight'"},
      {[](TensorFile& f) { f.tensors.erase("features.0.weight"); }, "no tensor 'features.0.weight'"},
      {[](TensorFile& f) { f.tensors["features.5.weight"].shape = {16, 4, 3, 3}; }, "expected [out, 8, 3, 3]"},
      {[](TensorFile& f) { f.tensors["features.7.bias"].shape = {15}; }, "features.7.bias has shape [15]"},
      {[](TensorFile& f) { f.tensors["lin2.weight"].shape = {1, 31, 1, 1}; }, "expected [1, 32, 1, 1]"},
      {[](TensorFile& f) { f.tensors["features.0.weight"].shape = {8, 3, 5, 5}; }, "neither VGG16"},
      {[](TensorFile& f) { f.tensors["features.10.weight"].values[7] = std::numeric_limits<float>::quiet_NaN(); },
       "'features.10.weight' holds a non-finite value at index 7"},
      {[](TensorFile& f) { f.tensors["lin0.weight"].values[0] = std::numeric_limits<float>::infinity(); }, "non-finite"},
      {[](TensorFile& f) { f.tensors["classifier.0.weight"] = {{1}, {0}}; }, "unexpected tensor 'classifier.0.weight'"},
      {[](TensorFile& f) { f.metadata["net"] = "alexnet"; }, "metadata says net 'alexnet'"},
  };
  for (const auto& c : cases) {
    TensorFile f = good;
    c.damage(f);
    const std::string msg = error_of(f);
    EXPECT_EQ(msg.rfind("w.safetensors: ", 0), 0u) << msg;
    EXPECT_NE(msg.find(c.expected), std::string::npos) << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  }
}

TEST(Lpips, CorruptOrMissingFileNamesIt) {
  const auto dir = test::scratch_dir();
  const std::string bytes = read_file(fixtures() / "alexnet_w8.safetensors");
  write_file_atomic(dir / "cut.safetensors", bytes.substr(0, bytes.size() / 2));
  for (const auto& path : {dir / "cut.safetensors", dir / "missing.safetensors"}) {
    try {
      Lpips::load(path);
      ADD_FAILURE() << "no error for " << path;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
    }
  }
}

TEST(Lpips, BadImagesGiveErrors) {
  const Lpips net = Lpips::load(fixtures() / "vgg16_w8.safetensors");
  const auto expect_error = [&](const Image& a, const Image& b, const std::string& expected) {
    try {
      net.distance(a, b, LpipsInputRange::unit, "view x.png");
      ADD_FAILURE() << "no error, expected " << expected;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("view x.png"), std::string::npos) << e.what();
    }
  };
  expect_error(Image(15, 20, 3, 0.5f), Image(15, 20, 3, 0.5f), "too small");
  expect_error(Image(20, 20, 3), Image(21, 20, 3), "sizes differ");
  expect_error(Image(20, 20, 1), Image(20, 20, 1), "expected RGB");
  Image nan(20, 20, 3, 0.5f);
  nan.at(4, 7, 1) = std::numeric_limits<float>::quiet_NaN();
  expect_error(Image(20, 20, 3, 0.5f), nan, "second image has a non-finite value at pixel (4, 7)");
  EXPECT_NO_THROW(net.distance(Image(16, 16, 3, 0.2f), Image(16, 16, 3, 0.7f), LpipsInputRange::unit));
}

TEST(Lpips, InputRangeNames) {
  EXPECT_EQ(parse_lpips_input_range("unit", "o"), LpipsInputRange::unit);
  EXPECT_EQ(parse_lpips_input_range("symmetric", "o"), LpipsInputRange::symmetric);
  EXPECT_EQ(parse_lpips_input_range("-1,1", "o"), LpipsInputRange::symmetric);
  EXPECT_THROW(parse_lpips_input_range("0-255", "o"), Error);
}

TEST(Avge, GeometricMeanOfTheThreeErrors) {
  // PSNR 20 dB -> MSE 0.01; SSIM 0.75 -> sqrt(0.25) = 0.5; LPIPS 0.125: cube root of 6.25e-4.
  EXPECT_NEAR(avge(20.0, 0.75, 0.125), 0.08549879733383486, 1e-15);
  EXPECT_EQ(avge(std::numeric_limits<double>::infinity(), 0.9, 0.1), 0.0);  // identical images
  EXPECT_EQ(avge(30.0, 1.0, 0.1), 0.0);
}

}  // namespace
}  // namespace d2gs
