#pragma once
// Seeded random numbers with results that do not depend on the standard library or the platform
// (std::normal_distribution does). One `--seed` drives a run; each consumer (camera order, dropout,
// densification, random init, ...) draws from its own stream derived from the seed and a fixed stream
// name, so adding draws in one place leaves the others unchanged.
#include <cmath>
#include <cstdint>
#include <string_view>

namespace d2gs {

// SplitMix64 (Steele, Lea and Flood 2014): a 64-bit counter passed through a mixing function. Rng draws
// its seed words from it; the demo scene (demo/synthetic_scene.cpp) uses it directly as a small
// stream of uniforms.
class SplitMix64 {
public:
  explicit SplitMix64(std::uint64_t seed = 0) : state_(seed) {}
  std::uint64_t next_u64() { return mix(state_ += 0x9e3779b97f4a7c15ull); }
  // Uniform in [0, 1) with 53 random bits.
  double uniform() { return static_cast<double>(next_u64() >> 11) * 0x1.0p-53; }
  // Uniform in [lo, hi).
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  // The finalizer alone (a 64-bit hash).
  static std::uint64_t mix(std::uint64_t z) {
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }

private:
  std::uint64_t state_;
};

class Rng {
public:
  explicit Rng(std::uint64_t seed = 0) { reseed(seed); }
  // A stream for one consumer: the same (seed, name) always gives the same sequence.
  static Rng stream(std::uint64_t seed, std::string_view name) {
    std::uint64_t h = 1469598103934665603ull;  // FNV-1a of the name, mixed with the seed
    for (char c : name) h = (h ^ static_cast<unsigned char>(c)) * 1099511628211ull;
    return Rng(seed ^ SplitMix64::mix(h));
  }

  void reseed(std::uint64_t seed) {
    SplitMix64 words(seed);
    for (auto& s : state_) s = words.next_u64();
    has_spare_ = false;
  }

  // xoshiro256**
  std::uint64_t next_u64() {
    const std::uint64_t result = rotl(state_[1] * 5, 7) * 9;
    const std::uint64_t t = state_[1] << 17;
    state_[2] ^= state_[0];
    state_[3] ^= state_[1];
    state_[1] ^= state_[2];
    state_[0] ^= state_[3];
    state_[2] ^= t;
    state_[3] = rotl(state_[3], 45);
    return result;
  }
  // Uniform in [0, 1) with 53 random bits.
  double uniform() { return static_cast<double>(next_u64() >> 11) * 0x1.0p-53; }
  // Uniform integer in [0, n) (n > 0), without modulo bias.
  std::uint64_t below(std::uint64_t n) {
    const std::uint64_t limit = ~std::uint64_t{0} - (~std::uint64_t{0} % n);
    std::uint64_t r;
    do r = next_u64(); while (r >= limit);
    return r % n;
  }
  // Standard normal (Marsaglia's polar method).
  double normal() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    double u, v, s;
    do {
      u = 2.0 * uniform() - 1.0;
      v = 2.0 * uniform() - 1.0;
      s = u * u + v * v;
    } while (s >= 1.0 || s == 0.0);
    const double f = std::sqrt(-2.0 * std::log(s) / s);
    spare_ = v * f;
    has_spare_ = true;
    return u * f;
  }
  bool bernoulli(double p) { return uniform() < p; }

  // The complete state (for checkpoints): four words, the spare normal's bits, and whether it is held.
  struct State {
    std::uint64_t words[4];
    double spare;
    bool has_spare;
  };
  State state() const { return {{state_[0], state_[1], state_[2], state_[3]}, spare_, has_spare_}; }
  void set_state(const State& s) {
    for (int i = 0; i < 4; ++i) state_[i] = s.words[i];
    spare_ = s.spare;
    has_spare_ = s.has_spare;
  }

private:
  static std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
  std::uint64_t state_[4]{};
  double spare_ = 0.0;
  bool has_spare_ = false;
};

}  // namespace d2gs
