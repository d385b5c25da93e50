// HTML building blocks: escaping, base64, embedded images (decoded back), error maps, pages.
#include <gtest/gtest.h>

#include "d2gs/core/error.hpp"
#include "d2gs/report/html.hpp"
#include "fake_run.hpp"
#include "test_paths.hpp"

namespace d2gs::report {
namespace {

TEST(Html, EscapesMarkupCharacters) {
  EXPECT_EQ(html_escape("<script>alert(\"x\" & 'y')</script>"),
            "&lt;script&gt;alert(&quot;x&quot; &amp; &#39;y&#39;)&lt;/script&gt;");
  EXPECT_EQ(html_escape("plain ü text"), "plain ü text");
}

TEST(Html, Base64MatchesRfc4648Vectors) {
  EXPECT_EQ(base64_encode(""), "");
  EXPECT_EQ(base64_encode("f"), "Zg==");
  EXPECT_EQ(base64_encode("fo"), "Zm8=");
  EXPECT_EQ(base64_encode("foo"), "Zm9v");
  EXPECT_EQ(base64_encode("foob"), "Zm9vYg==");
  EXPECT_EQ(base64_encode("fooba"), "Zm9vYmE=");
  EXPECT_EQ(base64_encode("foobar"), "Zm9vYmFy");
  EXPECT_EQ(base64_encode(std::string("\xff\x00\x80", 3)), "/wCA");
}

TEST(Html, PngDataUriDecodesToTheSamePixels) {
  const auto dir = test::scratch_dir();
  Image im(7, 5, 3);
  for (std::size_t i = 0; i < im.pixels.size(); ++i) im.pixels[i] = static_cast<float>(i % 256) / 255.0f;
  const std::string uri = image_data_uri(im, ImageEncoding::Png);
  const std::string prefix = "data:image/png;base64,";
  ASSERT_EQ(uri.rfind(prefix, 0), 0u);
  write_file_atomic(dir / "back.png", test::base64_decode(uri.substr(prefix.size())));
  const Image back = read_image(dir / "back.png");
  ASSERT_EQ(back.width, 7);
  ASSERT_EQ(back.height, 5);
  ASSERT_EQ(back.channels, 3);
  for (std::size_t i = 0; i < im.pixels.size(); ++i) EXPECT_NEAR(back.pixels[i], im.pixels[i], 0.5f / 255.0f) << i;
  // JPEG: a decodable image of the right size, colours close.
  const std::string jpeg = image_data_uri(test::gradient_image(40, 30, 0.3f), ImageEncoding::Jpeg);
  ASSERT_EQ(jpeg.rfind("data:image/jpeg;base64,", 0), 0u);
  write_file_atomic(dir / "back.jpg", test::base64_decode(jpeg.substr(23)));
  const Image j = read_image(dir / "back.jpg");
  EXPECT_EQ(j.width, 40);
  EXPECT_NEAR(j.at(20, 15, 2), 0.3f, 0.05f);
  EXPECT_THROW(image_data_uri(Image{}), Error);
}

TEST(Html, ErrorMapIsDarkWhereEqualAndBrightWhereFarOff) {
  const Image a = test::gradient_image(8, 6, 0.2f);
  Image b = a;
  for (int y = 0; y < 6; ++y)
    for (int c = 0; c < 3; ++c) b.at(7, y, c) = 1.0f - a.at(7, y, c) > 0.5f ? 1.0f : 0.0f;
  const Image e = error_map(b, a, 0.25f);
  EXPECT_EQ(e.channels, 3);
  EXPECT_LT(e.at(0, 0, 0) + e.at(0, 0, 1) + e.at(0, 0, 2), 0.05f);  // no error: black
  EXPECT_GT(e.at(7, 0, 0), 0.9f);                                   // large error: pale yellow
  EXPECT_GT(e.at(7, 0, 1), 0.9f);
  EXPECT_THROW(error_map(a, test::gradient_image(4, 6, 0.2f)), Error);
}

TEST(Html, PageHasSectionsNavigationAndNoOutsideResources) {
  HtmlPage page("Run <a&b>", "sub \"title\"");
  page.add_section("metrics", "Test <metrics>", html_table({"view", "PSNR"}, {{"x<y", "1.0"}}));
  page.add_section("views", "Views", "<p>body</p>\n");
  const std::string html = page.str();
  EXPECT_EQ(test::check_balanced(html), "") << html;
  EXPECT_NE(html.find("<title>Run &lt;a&amp;b&gt;</title>"), std::string::npos);
  EXPECT_NE(html.find("sub &quot;title&quot;"), std::string::npos);
  EXPECT_NE(html.find("<section id=\"metrics\">"), std::string::npos);
  EXPECT_NE(html.find("<a href=\"#views\">Views</a>"), std::string::npos);
  EXPECT_NE(html.find("<td>x&lt;y</td>"), std::string::npos);
  EXPECT_EQ(html.find("Run <a&b>"), std::string::npos);
  EXPECT_EQ(html.find("<link"), std::string::npos);
  EXPECT_EQ(html.find("src=\"http"), std::string::npos);
  EXPECT_EQ(html.find("<script src"), std::string::npos);
  EXPECT_EQ(html.find("url("), std::string::npos);
  EXPECT_NE(html.find("load-error"), std::string::npos);  // the in-page image check
}

}  // namespace
}  // namespace d2gs::report
