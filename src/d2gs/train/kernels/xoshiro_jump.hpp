#pragma once
// The CPU's random stream (core/random.hpp: Rng, xoshiro256**) drawn in parallel, the same numbers in the
// same order: xoshiro256's state transition s → M·s is linear over GF(2), so the state k draws ahead is
// p(M)·s for the polynomial p = x^k mod P (P: M's characteristic polynomial, degree 256), and p(M)·s is
// 256 steps of the generator with the states of p's set coefficients XORed together (xoshiro's own
// jump() is this for k = 2^128). A kernel thread that starts j·L draws into the stream applies the
// polynomials of the set bits of j (for L·2^b draws each) and then draws its L values in order.
//
// xoshiro_next and xoshiro_uniform repeat Rng::next_u64 and Rng::uniform for a bare state (core/ cannot
// use D2GS_HD); tests/cuda checks them against Rng draw for draw.
#include <stdint.h>

#include <array>
#include <vector>

#include "d2gs/core/random.hpp"
#include "d2gs/core/host_device.hpp"

namespace d2gs::train_kernels {

D2GS_HD uint64_t xoshiro_rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

// Rng::next_u64 on the state s[4].
D2GS_HD uint64_t xoshiro_next(uint64_t* s) {
  const uint64_t result = xoshiro_rotl(s[1] * 5, 7) * 9;
  const uint64_t t = s[1] << 17;
  s[2] ^= s[0];
  s[3] ^= s[1];
  s[1] ^= s[2];
  s[0] ^= s[3];
  s[2] ^= t;
  s[3] = xoshiro_rotl(s[3], 45);
  return result;
}

// Rng::uniform: 53 random bits in [0, 1).
D2GS_HD double xoshiro_uniform(uint64_t* s) { return static_cast<double>(xoshiro_next(s) >> 11) * 0x1.0p-53; }

// s ← p(M)·s for a polynomial p of degree < 256 (p[w] bit b: the coefficient of x^(64w + b)).
D2GS_HD void xoshiro_apply(uint64_t* s, const uint64_t* p) {
  uint64_t t[4] = {0, 0, 0, 0};
  for (int w = 0; w < 4; ++w)
    for (int b = 0; b < 64; ++b) {
      if (p[w] & (uint64_t{1} << b)) {
        t[0] ^= s[0];
        t[1] ^= s[1];
        t[2] ^= s[2];
        t[3] ^= s[3];
      }
      xoshiro_next(s);
    }
  for (int k = 0; k < 4; ++k) s[k] = t[k];
}

using XoshiroPolynomial = std::array<uint64_t, 4>;

// x^draws mod P: the polynomial that moves a state `draws` draws ahead.
XoshiroPolynomial xoshiro_jump_polynomial(uint64_t draws);
// x^(2^log2_draws) mod P (xoshiro256's jump() and long_jump() are 2^128 and 2^192 draws).
XoshiroPolynomial xoshiro_jump_polynomial_pow2(int log2_draws);
// The polynomials for chunk · 2^b draws, b = 0 … bits − 1, 4 words each (a kernel's jump table).
std::vector<uint64_t> xoshiro_jump_table(uint64_t chunk, int bits);
// The stream `draws` draws ahead: rng's state as if it had drawn `draws` uniforms.
void advance(Rng& rng, uint64_t draws);

}  // namespace d2gs::train_kernels
