#include "d2gs/train/kernels/xoshiro_jump.hpp"

#include "d2gs/core/error.hpp"

namespace d2gs::train_kernels {
namespace {

constexpr int kDegree = 256;

// Polynomials over GF(2) of degree ≤ 511, bit k = the coefficient of x^k.
struct Poly512 {
  uint64_t w[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  bool bit(int k) const { return (w[k / 64] >> (k % 64)) & 1u; }
  void flip(int k) { w[k / 64] ^= uint64_t{1} << (k % 64); }
};

// xoshiro256's characteristic polynomial P (degree 256; bit 256 set), by Berlekamp–Massey on 512 values
// of one bit of the state: that bit's sequence satisfies P's recurrence, and its minimal polynomial is P
// itself when it has degree 256 (P is primitive: the generator has period 2^256 − 1).
Poly512 characteristic_polynomial() {
  uint64_t s[4];
  SplitMix64 words(0x5eed);
  for (auto& v : s) v = words.next_u64();
  std::vector<int> bits(2 * kDegree);
  for (auto& b : bits) {
    b = static_cast<int>(s[0] & 1u);
    xoshiro_next(s);
  }
  // Connection polynomial C(x) = 1 + c1·x + … + cL·x^L with b_n = Σ c_i·b_{n−i}.
  std::vector<int> c(bits.size() + 1, 0), prev(bits.size() + 1, 0);
  c[0] = prev[0] = 1;
  int length = 0, shift = 1;
  for (std::size_t n = 0; n < bits.size(); ++n) {
    int d = bits[n];
    for (int i = 1; i <= length; ++i) d ^= c[static_cast<std::size_t>(i)] & bits[n - static_cast<std::size_t>(i)];
    if (d == 0) {
      ++shift;
      continue;
    }
    const std::vector<int> saved = c;
    for (std::size_t i = 0; i + static_cast<std::size_t>(shift) < c.size(); ++i)
      c[i + static_cast<std::size_t>(shift)] ^= prev[i];
    if (2 * length <= static_cast<int>(n)) {
      length = static_cast<int>(n) + 1 - length;
      prev = saved;
      shift = 1;
    } else {
      ++shift;
    }
  }
  if (length != kDegree) fail("xoshiro jump: the characteristic polynomial has degree {}, not 256", length);
  Poly512 p;  // P(x) = x^256 + c1·x^255 + … + c256
  for (int i = 0; i <= kDegree; ++i)
    if (c[static_cast<std::size_t>(i)]) p.flip(kDegree - i);
  return p;
}

const Poly512& characteristic() {
  static const Poly512 p = characteristic_polynomial();
  return p;
}

// r ^= p·x^shift (the bits of the product above 511 are dropped: callers have none).
void xor_shifted(Poly512& r, const Poly512& p, int shift) {
  const int word = shift / 64, offset = shift % 64;
  for (int k = 0; k + word < 8; ++k) {
    r.w[k + word] ^= p.w[k] << offset;
    if (offset && k + word + 1 < 8) r.w[k + word + 1] ^= p.w[k] >> (64 - offset);
  }
}

// a·b mod P for a, b of degree < 256.
Poly512 mulmod(const Poly512& a, const Poly512& b) {
  Poly512 r;
  for (int i = 0; i < kDegree; ++i)
    if (a.bit(i)) xor_shifted(r, b, i);
  const Poly512& p = characteristic();
  for (int k = 2 * kDegree - 2; k >= kDegree; --k)
    if (r.bit(k)) xor_shifted(r, p, k - kDegree);  // r −= x^(k − 256)·P
  return r;
}

}  // namespace

XoshiroPolynomial xoshiro_jump_polynomial(uint64_t draws) {
  Poly512 r;
  r.flip(0);  // 1
  for (int bit = 63; bit >= 0; --bit) {
    r = mulmod(r, r);
    if ((draws >> bit) & 1u) {  // r·x
      Poly512 x;
      x.flip(1);
      r = mulmod(r, x);
    }
  }
  return {r.w[0], r.w[1], r.w[2], r.w[3]};
}

XoshiroPolynomial xoshiro_jump_polynomial_pow2(int log2_draws) {
  Poly512 r;
  r.flip(1);  // x
  for (int k = 0; k < log2_draws; ++k) r = mulmod(r, r);
  return {r.w[0], r.w[1], r.w[2], r.w[3]};
}

std::vector<uint64_t> xoshiro_jump_table(uint64_t chunk, int bits) {
  std::vector<uint64_t> table;
  table.reserve(4 * static_cast<std::size_t>(bits));
  for (int b = 0; b < bits; ++b)
    for (uint64_t w : xoshiro_jump_polynomial(chunk << b)) table.push_back(w);
  return table;
}

void advance(Rng& rng, uint64_t draws) {
  Rng::State state = rng.state();
  const XoshiroPolynomial p = xoshiro_jump_polynomial(draws);
  xoshiro_apply(state.words, p.data());
  rng.set_state(state);
}

}  // namespace d2gs::train_kernels
