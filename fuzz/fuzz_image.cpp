// libFuzzer target: image decoding (d2gs::decode_image: OpenCV's codecs plus the JPEG integrity check) and
// the header size reader, on arbitrary bytes. Any input must either decode or throw d2gs::Error; a decoded
// image holds width × height × channels values in [0, 1], and for PNG and JPEG the header size
// (read_image_size) is the decoded size.
// OpenCV is not instrumented: run with OPENCV_IO_MAX_IMAGE_PIXELS set low (scripts/fuzz.sh does) so
// that a header claiming a huge image is refused instead of exhausting the fuzzer's memory.
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

#include "d2gs/core/error.hpp"
#include "d2gs/core/image.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  try {
    const d2gs::Image image = d2gs::decode_image(bytes, "fuzz.img");
    if (image.width <= 0 || image.height <= 0 || image.channels < 1 || image.channels > 4) std::abort();
    if (image.pixels.size() != static_cast<std::size_t>(image.width) * image.height * image.channels) std::abort();
    for (const float v : image.pixels)
      if (!(v >= 0.0f && v <= 1.0f)) std::abort();
    const bool png = size >= 8 && bytes.substr(1, 3) == "PNG";
    const bool jpeg = size >= 2 && data[0] == 0xFF && data[1] == 0xD8;
    if (png || jpeg) {
      static const std::filesystem::path file =
          std::filesystem::temp_directory_path() / ("d2gs-fuzz-image-" + std::to_string(::getpid()));
      {
        std::ofstream out(file, std::ios::binary | std::ios::trunc);
        out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
      }
      const d2gs::ImageSize header = d2gs::read_image_size(file);
      if (header.width != image.width || header.height != image.height) std::abort();
    }
  } catch (const d2gs::Error&) {
  }
  return 0;
}
