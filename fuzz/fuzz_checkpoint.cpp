// libFuzzer target: the checkpoint decoder (train/checkpoint.hpp) and the resume checks on arbitrary
// bytes. Each input is tried twice: as it is (the magic, size and CRC-32 checks) and with its last four
// bytes replaced by the CRC-32 of the rest, so that the fuzzer reaches the header and array parsing
// behind the checksum. Any input must either decode or throw d2gs::Error; a decoded checkpoint is
// consistent (arrays shaped as the header says), its encoding decodes to itself, and check_resume
// against a fixed run either accepts it or throws d2gs::Error.
#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>
#include <string_view>

#include "d2gs/core/checksum.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/train/checkpoint.hpp"

namespace {

void check(std::string_view bytes) {
  try {
    const d2gs::Checkpoint c = d2gs::decode_checkpoint(bytes, "fuzz.bin");
    const auto& s = c.state;
    const std::size_t n = s.model.size();
    if (s.exp_avg.size() != n || s.exp_avg_sq.size() != n || s.grad_sums.size() != n || s.grad_counts.size() != n)
      std::abort();
    // Encoding is canonical: what decodes re-encodes to bytes that decode to the same encoding.
    const std::string again = d2gs::encode_checkpoint(c.run, c.state);
    const d2gs::Checkpoint d = d2gs::decode_checkpoint(again, "fuzz.bin");
    if (d2gs::encode_checkpoint(d.run, d.state) != again) std::abort();
    try {  // against the checkpoint's own run, so that the checks of the state are reached
      (void)d2gs::check_resume("fuzz.bin", c, c.run, std::max(s.iteration, s.iterations));
    } catch (const d2gs::Error&) {
    }
  } catch (const d2gs::Error&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  check(bytes);
  if (size >= 4) {
    std::string fixed(bytes);
    const std::uint32_t crc = d2gs::crc32(std::string_view(fixed).substr(0, size - 4));
    std::memcpy(fixed.data() + size - 4, &crc, 4);
    check(fixed);
  }
  return 0;
}
