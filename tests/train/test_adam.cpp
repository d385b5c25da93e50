#include <gtest/gtest.h>

#include <cmath>

#include "d2gs/model/rows.hpp"
#include "d2gs/train/adam.hpp"

namespace d2gs {
namespace {

TEST(Adam, FirstStepsFollowTorchSemantics) {
  Gaussians model;
  model.resize(2, 0);
  model.opacity_logits = {1.0f, -1.0f};
  Gaussians grads = model;
  zero_values(grads);
  AdamState state = Adam::make_state(model);
  LearningRates lr;
  lr.opacity = 0.05f;

  // Step 1: m̂ = g, v̂ = g², so the update is lr·g/|g| = lr·sign(g) (eps 1e-15 is negligible).
  grads.opacity_logits = {0.3f, -2.0f};
  Adam::step(model, grads, state, lr, 0.0f);
  EXPECT_NEAR(model.opacity_logits[0], 1.0f - 0.05f, 1e-6f);
  EXPECT_NEAR(model.opacity_logits[1], -1.0f + 0.05f, 1e-6f);

  // Step 2 with g2: m = 0.09·g1 + 0.1·g2, v = 0.000999·g1² + 0.001·g2², bias1 = 0.19, bias2 = 1 − 0.999².
  grads.opacity_logits = {0.1f, 0.0f};
  Adam::step(model, grads, state, lr, 0.0f);
  const double m = 0.09 * 0.3 + 0.1 * 0.1, v = 0.000999 * 0.09 + 0.001 * 0.01;
  const double update = 0.05 / 0.19 * m / (std::sqrt(v) / std::sqrt(1 - 0.999 * 0.999) + 1e-15);
  EXPECT_NEAR(model.opacity_logits[0], 0.95 - update, 1e-6);
  // A zero gradient still moves the parameter by its momentum (dense Adam, as the original).
  EXPECT_NE(model.opacity_logits[1], -0.95f);
  EXPECT_EQ(state.step, 2);
}

TEST(Adam, RejectsMisalignedState) {
  Gaussians model;
  model.resize(3, 1);
  AdamState state = Adam::make_state(model);
  Gaussians grads = model;
  keep_rows(grads, {1, 0, 1});
  EXPECT_ANY_THROW(Adam::step(model, grads, state, LearningRates{}, 1e-4f));
}

TEST(Adam, PositionScheduleIsLogLinear) {
  EXPECT_NEAR(position_lr(1.6e-4, 1.6e-6, 0, 10000), 1.6e-4, 1e-12);
  EXPECT_NEAR(position_lr(1.6e-4, 1.6e-6, 10000, 10000), 1.6e-6, 1e-14);
  EXPECT_NEAR(position_lr(1.6e-4, 1.6e-6, 5000, 10000), 1.6e-5, 1e-12);  // geometric mean halfway
  EXPECT_NEAR(position_lr(1.6e-4, 1.6e-6, 20000, 10000), 1.6e-6, 1e-14);
}

TEST(Rows, KeepGatherAppendStayAligned) {
  Gaussians g;
  g.resize(4, 1);
  for (std::size_t i = 0; i < 4; ++i) {
    g.opacity_logits[i] = static_cast<float>(i);
    g.means[i * 3 + 2] = 10.0f * static_cast<float>(i);
    g.sh_rest[i * 9 + 8] = 100.0f * static_cast<float>(i);
  }
  Gaussians picked = gather_rows(g, {3, 1, 1});
  EXPECT_EQ(picked.opacity_logits, (std::vector<float>{3, 1, 1}));
  EXPECT_EQ(picked.sh_rest[8], 300.0f);
  keep_rows(g, {1, 0, 1, 0});
  EXPECT_EQ(g.opacity_logits, (std::vector<float>{0, 2}));
  EXPECT_EQ(g.means[5], 20.0f);
  append_rows(g, picked);
  g.validate();
  EXPECT_EQ(g.size(), 5u);
  EXPECT_EQ(g.sh_rest[4 * 9 + 8], 100.0f);
  EXPECT_ANY_THROW(gather_rows(g, {7}));
}

}  // namespace
}  // namespace d2gs
