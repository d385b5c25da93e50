#include <string>
#include <utility>

#include <gtest/gtest.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/image.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {

TEST(Image, PngRoundTripIsExactAt8Bits) {
  const auto dir = test::scratch_dir();
  Image img(5, 3, 3);
  for (std::size_t i = 0; i < img.pixels.size(); ++i) img.pixels[i] = static_cast<float>((i * 37) % 256) / 255.0f;
  write_image(dir / "a.png", img);
  const Image back = read_image(dir / "a.png");
  ASSERT_EQ(back.width, 5);
  ASSERT_EQ(back.height, 3);
  ASSERT_EQ(back.channels, 3);
  for (std::size_t i = 0; i < img.pixels.size(); ++i) EXPECT_FLOAT_EQ(back.pixels[i], img.pixels[i]);
  const auto size = read_image_size(dir / "a.png");
  EXPECT_EQ(size.width, 5);
  EXPECT_EQ(size.height, 3);
}

TEST(Image, HeaderSizeOfRealPngAndJpeg) {
  const auto fern = read_image_size(test::shared_data() / "nerf_llff_data/fern/images_8/image000.png");
  EXPECT_EQ(fern.width, 504);
  EXPECT_EQ(fern.height, 378);
  const auto room = read_image_size(test::shared_data() / "llff_nex_reprocessed/room/images/img001.JPG");
  const auto decoded = read_image(test::shared_data() / "llff_nex_reprocessed/room/images/img001.JPG");
  EXPECT_EQ(room.width, decoded.width);
  EXPECT_EQ(room.height, decoded.height);
}

// Stray bytes between a JPEG's segments (fill 0xFF, a stuffed "FF 00", garbage) are skipped by libjpeg
// with a warning and the image decodes. The header reader must find the same frame size as the decoder:
// a hand-written marker walk read "FF 00" as a segment and returned a size from the wrong bytes (found by
// fuzz_image; its input is in fuzz/corpus/fuzz_image/stray-ff00-before-dqt.jpg).
TEST(Image, HeaderSizeSkipsStrayBytesBetweenJpegSegmentsAsTheDecoderDoes) {
  const auto dir = test::scratch_dir();
  const std::string jpeg = read_file(test::shared_data() / "llff_nex_reprocessed/room/images/img001.JPG");
  // After SOI and the first segment (APP0 or APP1), insert stray bytes before the next marker.
  ASSERT_EQ(static_cast<unsigned char>(jpeg[2]), 0xFF);
  const std::size_t first_len = (static_cast<unsigned char>(jpeg[4]) << 8) | static_cast<unsigned char>(jpeg[5]);
  const std::size_t next = 4 + first_len;
  ASSERT_EQ(static_cast<unsigned char>(jpeg[next]), 0xFF);
  const std::string stray("\xFF\xFF\xFF\x00\x00\x13\x37\xFF\x00\x00", 10);
  const std::string damaged = jpeg.substr(0, next) + stray + jpeg.substr(next);
  write_file_atomic(dir / "stray.jpg", damaged);
  const Image decoded = read_image(dir / "stray.jpg");
  const ImageSize header = read_image_size(dir / "stray.jpg");
  EXPECT_EQ(header.width, decoded.width);
  EXPECT_EQ(header.height, decoded.height);
  EXPECT_EQ(decoded.width, 996);
  // And the fuzzer's own input, which decodes (a 12 x 9 frame after the stray bytes).
  const auto finding = test::source_dir() / "fuzz/corpus/fuzz_image/stray-ff00-before-dqt.jpg";
  const Image image = read_image(finding);
  const ImageSize size = read_image_size(finding);
  EXPECT_EQ(size.width, image.width);
  EXPECT_EQ(size.height, image.height);
}

// A few kilobytes can declare gigapixels (a decompression bomb): a frame above kMaxImagePixels is refused
// from its header, naming the file and the size, by the decoder and by the header reader, before libpng or
// libjpeg allocate anything for it.
TEST(Image, AFrameAboveThePixelLimitIsRefusedFromItsHeader) {
  const auto dir = test::scratch_dir();
  const auto put16 = [](std::string& b, std::size_t at, int v) {
    b[at] = static_cast<char>(v >> 8);
    b[at + 1] = static_cast<char>(v & 255);
  };
  std::string png = read_file(test::shared_data() / "nerf_llff_data/fern/images_8/image000.png");
  put16(png, 18, 20000);  // IHDR width and height (big-endian 32-bit at 16 and 20)
  put16(png, 22, 20000);
  std::string jpeg = read_file(test::shared_data() / "llff_nex_reprocessed/room/images/img001.JPG");
  std::size_t sof = 2;  // walk the segments to the frame header (SOF0..SOF2)
  while (sof + 4 < jpeg.size() && !(static_cast<unsigned char>(jpeg[sof + 1]) >= 0xC0 &&
                                     static_cast<unsigned char>(jpeg[sof + 1]) <= 0xC2))
    sof += 2 + ((static_cast<unsigned char>(jpeg[sof + 2]) << 8) | static_cast<unsigned char>(jpeg[sof + 3]));
  ASSERT_LT(sof + 9, jpeg.size());
  put16(jpeg, sof + 5, 20000);  // height, then width
  put16(jpeg, sof + 7, 20000);
  for (const auto& [name, bytes] : {std::pair{"bomb.png", png}, std::pair{"bomb.jpg", jpeg}}) {
    write_file_atomic(dir / name, bytes);
    const std::string expected = (dir / name).string() + ": image is 20000x20000: more than the 268435456 pixels d2gs decodes";
    for (int reader = 0; reader < 3; ++reader) {
      try {
        if (reader == 0) read_image(dir / name);
        if (reader == 1) decode_image(bytes, dir / name);
        if (reader == 2) read_image_size(dir / name);
        ADD_FAILURE() << name << " taken by reader " << reader;
      } catch (const Error& e) {
        EXPECT_EQ(std::string(e.what()), expected) << reader;
      }
    }
  }
}

TEST(Image, RgbOrderAndAreaResize) {
  const Image fern = read_image(test::shared_data() / "nerf_llff_data/fern/images_4/image000.png");
  const Image half = resize_area(fern, fern.width / 2, fern.height / 2);
  // Area resampling by 2 is the mean of each 2x2 block.
  const float expect = 0.25f * (fern.at(10, 6, 0) + fern.at(11, 6, 0) + fern.at(10, 7, 0) + fern.at(11, 7, 0));
  EXPECT_NEAR(half.at(5, 3, 0), expect, 1e-6f);
}

TEST(Image, AreaResizeOfADepthMapIgnoresItsZeros) {
  // 4x2 → 2x1: block 0 holds depths 2, 4 and two zeros (half covered: mean of the valid ones, 3; a plain
  // area resize would give 1.5); block 1 holds one depth of 8 (a quarter covered: no value).
  Image depth(4, 2, 1);
  depth.pixels = {2.0f, 0.0f, 8.0f, 0.0f,  //
                  0.0f, 4.0f, 0.0f, 0.0f};
  const Image out = resize_area_nonzero(depth, 2, 1);
  EXPECT_FLOAT_EQ(out.pixels[0], 3.0f);
  EXPECT_FLOAT_EQ(out.pixels[1], 0.0f);
  EXPECT_FLOAT_EQ(resize_area(depth, 2, 1).pixels[0], 1.5f);
  // Fully valid: the plain area resize.
  Image full(4, 2, 1, 5.0f);
  full.pixels[0] = 1.0f;
  EXPECT_FLOAT_EQ(resize_area_nonzero(full, 2, 1).pixels[0], resize_area(full, 2, 1).pixels[0]);
  EXPECT_THROW(resize_area_nonzero(Image(4, 2, 3), 2, 1), Error);
}

TEST(Image, CorruptAndMissingFilesAreErrors) {
  const auto dir = test::scratch_dir();
  write_file_atomic(dir / "bad.png", "\x89PNG\r\n\x1a\nthis is not a png");
  EXPECT_THROW(read_image(dir / "bad.png"), Error);
  EXPECT_THROW(read_image_size(dir / "bad.png"), Error);
  EXPECT_THROW(read_image(dir / "missing.png"), Error);
  try {
    read_image(dir / "bad.png");
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.png"), std::string::npos);
  }
}

// A truncated or damaged PNG is named by d2gs from its chunk structure before libpng sees it (libpng printed
// its own "libpng error: ..." line on stderr before d2gs's message).
TEST(Image, TruncatedOrDamagedPngIsNamedWithoutLibpngsOwnLine) {
  const std::string png = read_file(test::shared_data() / "nerf_llff_data/fern/images_8/image000.png");
  ASSERT_NO_THROW(decode_image(png, "whole.png"));
  const auto message = [](const std::string& bytes) {
    testing::internal::CaptureStderr();
    std::string what;
    try {
      decode_image(bytes, "x.png");
    } catch (const Error& e) {
      what = e.what();
    }
    const std::string err = testing::internal::GetCapturedStderr();
    EXPECT_EQ(err, "") << "libpng spoke: " << err;
    return what;
  };
  EXPECT_EQ(message(png.substr(0, png.size() * 2 / 3)), "x.png: corrupt or truncated PNG (truncated: the file ends inside chunk IDAT)");
  EXPECT_EQ(message(png.substr(0, png.size() - 12)), "x.png: corrupt or truncated PNG (truncated: no IEND chunk)");
  std::string flipped = png;
  flipped[png.size() / 2] = static_cast<char>(flipped[png.size() / 2] ^ 0x10);
  EXPECT_EQ(message(flipped), "x.png: corrupt or truncated PNG (chunk IDAT is damaged (CRC mismatch))");
  EXPECT_EQ(message(png.substr(0, 8) + std::string(16, 'x')).rfind("x.png: corrupt or truncated PNG (", 0), 0u);
}

// The fuzzer's finding: bytes that are neither PNG nor JPEG but carry DICOM's magic at byte 128 made OpenCV
// hand them to GDCM, which aborted the process. Only PNG and JPEG are decoded; anything else is a one-line
// error naming the file, whatever decoder OpenCV would have chosen.
TEST(Image, OtherFormatsAreRefusedBeforeOpenCvChoosesADecoder) {
  const auto dir = test::scratch_dir();
  const auto finding = test::source_dir() / "fuzz/corpus/fuzz_image/dicom-magic-at-128.bin";
  ASSERT_EQ(read_file(finding).substr(128, 4), "DICM");
  // A BMP (which OpenCV would decode) is refused too: the scenes' image folders hold PNG and JPEG.
  const std::string bmp = std::string("BM") + std::string(60, '\0');
  write_file_atomic(dir / "a.bmp", bmp);
  for (const auto& path : {finding, dir / "a.bmp"}) {
    try {
      read_image(path);
      ADD_FAILURE() << path << " was decoded";
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(path.string() + ": not a PNG or JPEG file"), std::string::npos) << msg;
    }
    EXPECT_THROW(read_image_size(path), Error);
  }
}

// A real photograph (room, JPEG) cut short: libjpeg pads the missing rows with grey and only warns, and
// OpenCV passes the image on. It must be an error naming the file, as for a truncated PNG.
TEST(Image, TruncatedJpegIsAnErrorNamingTheFile) {
  const auto dir = test::scratch_dir();
  const std::string jpeg = read_file(test::shared_data() / "llff_nex_reprocessed/room/images/img001.JPG");
  ASSERT_GT(jpeg.size(), 10000u);
  const Image whole = decode_image(jpeg, "img001.JPG");
  EXPECT_EQ(whole.width, 996);
  EXPECT_EQ(whole.height, 746);
  for (const double kept : {0.6, 0.95}) {
    const auto path = dir / "cut.jpg";
    write_file_atomic(path, std::string_view(jpeg).substr(0, static_cast<std::size_t>(kept * jpeg.size())));
    try {
      read_image(path);
      ADD_FAILURE() << "a JPEG cut to " << kept << " of its bytes was decoded";
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(path.string()), std::string::npos) << msg;
      EXPECT_NE(msg.find("truncated JPEG"), std::string::npos) << msg;
      EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
    }
    // The header is intact, so the size is still read without decoding.
    EXPECT_EQ(read_image_size(path).width, 996);
  }
  // Only the end-of-image marker missing: the data is complete but the file is still cut.
  write_file_atomic(dir / "no_eoi.jpg", std::string_view(jpeg).substr(0, jpeg.size() - 2));
  EXPECT_THROW(read_image(dir / "no_eoi.jpg"), Error);
  // Bytes after the end-of-image marker (some cameras append data) leave the image whole.
  write_file_atomic(dir / "trailer.jpg", jpeg + "trailing bytes");
  const Image trailer = read_image(dir / "trailer.jpg");
  EXPECT_EQ(trailer.pixels, whole.pixels);
  // A file that is not an image at all, and an empty one.
  write_file_atomic(dir / "empty.jpg", "");
  EXPECT_THROW(read_image(dir / "empty.jpg"), Error);
  write_file_atomic(dir / "text.jpg", "\xFF\xD8\xFFnot really a jpeg");
  EXPECT_THROW(read_image(dir / "text.jpg"), Error);
}

}  // namespace
}  // namespace d2gs
