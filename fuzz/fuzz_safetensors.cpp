// libFuzzer target: the safetensors reader (LPIPS weights) on arbitrary bytes. Any input must either parse
// or throw d2gs::Error; what parses must survive a write/parse round trip bit for bit (values are F32
// after reading, so writing them as F32 and reading again changes nothing).
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string_view>

#include "d2gs/core/error.hpp"
#include "d2gs/core/safetensors.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  try {
    const d2gs::TensorFile f = d2gs::parse_safetensors(bytes, "fuzz.safetensors");
    for (const auto& [name, t] : f.tensors) {
      std::uint64_t count = 1;
      for (const auto d : t.shape) {
        if (d < 0) std::abort();
        count *= static_cast<std::uint64_t>(d);
      }
      if (count != t.values.size()) std::abort();
    }
    const d2gs::TensorFile back = d2gs::parse_safetensors(d2gs::serialize_safetensors(f), "round-trip");
    if (back.metadata != f.metadata || back.tensors.size() != f.tensors.size()) std::abort();
    for (const auto& [name, t] : f.tensors) {
      const auto it = back.tensors.find(name);
      if (it == back.tensors.end() || it->second.shape != t.shape || it->second.values.size() != t.values.size()) std::abort();
      if (!t.values.empty() && std::memcmp(it->second.values.data(), t.values.data(), 4 * t.values.size()) != 0) std::abort();
    }
  } catch (const d2gs::Error&) {
  }
  return 0;
}
