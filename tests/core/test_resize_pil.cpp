// resize_pil_bicubic against Pillow's Image.resize on real scene images (fixtures from
// tools/make_pil_resize_fixture.py): every byte must agree.
#include <cmath>
#include <cstdint>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/resize_pil.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {

int byte(float v) { return static_cast<int>(std::lround(v * 255.0f)); }

TEST(ResizePil, MatchesPillowByteForByteOnRealImages) {
  const auto fixtures = test::source_dir() / "tests/core/fixtures";
  const auto manifest = nlohmann::json::parse(read_file(fixtures / "pil_resize.json"));
  ASSERT_EQ(manifest["cases"].size(), 3u);
  for (const auto& c : manifest["cases"]) {
    const std::string name = c["name"];
    SCOPED_TRACE(name);
    const Image src = read_image(test::shared_data() / c["source"].get<std::string>());
    const int w = c["width"], h = c["height"];
    const Image out = resize_pil_bicubic(src, w, h);
    ASSERT_EQ(out.width, w);
    ASSERT_EQ(out.height, h);
    ASSERT_EQ(out.channels, 3);
    std::int64_t sum = 0;
    for (float v : out.pixels) sum += byte(v);
    EXPECT_EQ(sum, c["byte_sum"].get<std::int64_t>());
    const Image ref = read_image(fixtures / ("pil_resize_" + name + ".png"));
    int x0 = 0, y0 = 0;
    if (!c["crop"].is_null()) x0 = c["crop"][0], y0 = c["crop"][1];
    std::size_t differ = 0;
    for (int y = 0; y < ref.height; ++y)
      for (int x = 0; x < ref.width; ++x)
        for (int k = 0; k < 3; ++k) differ += byte(out.at(x0 + x, y0 + y, k)) != byte(ref.at(x, y, k));
    EXPECT_EQ(differ, 0u) << "of " << ref.pixels.size() << " values";
  }
}

TEST(ResizePil, KeepsConstantsAndIdentity) {
  Image flat(37, 23, 3, 0.0f);
  for (std::size_t i = 0; i < flat.pixels.size(); ++i) flat.pixels[i] = static_cast<float>(40 + i % 3 * 70) / 255.0f;
  for (const auto& [w, h] : {std::pair{18, 11}, std::pair{5, 3}, std::pair{37, 23}, std::pair{80, 50}}) {
    const Image out = resize_pil_bicubic(flat, w, h);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int k = 0; k < 3; ++k) ASSERT_EQ(byte(out.at(x, y, k)), 40 + k * 70) << w << "x" << h;
  }
  EXPECT_THROW(resize_pil_bicubic(flat, 0, 3), Error);
}

}  // namespace
}  // namespace d2gs
