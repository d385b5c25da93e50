// Sparse-view split (method.md §3): banker's rounding, linspace picks, LLFF/COLMAP hold-out, Blender's
// DietNeRF selection and every impossible request.
#include <gtest/gtest.h>

#include <numeric>

#include "d2gs/scene/split.hpp"
#include "scene_test_util.hpp"

namespace d2gs {
namespace {

// A scene with n cameras named in order (metadata only: make_split looks at nothing else).
Scene synthetic_scene(int n, SceneFormat format = SceneFormat::Llff) {
  Scene s;
  s.format = format;
  s.root = "synthetic";
  for (int i = 0; i < n; ++i) {
    Camera c;
    c.image_name = "img" + std::to_string(i);
    s.cameras.push_back(c);
  }
  return s;
}

std::vector<int> iota(int n, int start = 0) {
  std::vector<int> v(static_cast<std::size_t>(n));
  std::iota(v.begin(), v.end(), start);
  return v;
}

TEST(Split, RoundHalfEvenMatchesNumpy) {
  // Expected values from /usr/bin/python3 with NumPy 1.24.2: [int(np.round(x)) for x in xs].
  const double xs[] = {0.5, 1.5, 2.5, -0.5, -1.5, -2.5, 3.5, 0.49999999999999994, 2.5000000000000004,
                       1e15 + 0.5, 7.0, -7.2, 8.5};
  const long expected[] = {0, 2, 2, 0, -2, -2, 4, 0, 3, 1000000000000000, 7, -7, 8};
  for (std::size_t i = 0; i < std::size(xs); ++i) EXPECT_EQ(round_half_even(xs[i]), expected[i]) << xs[i];
  EXPECT_THROW(round_half_even(std::nan("")), Error);
  EXPECT_THROW(round_half_even(1e300), Error);
}

TEST(Split, LinspacePickMatchesNumpy) {
  // Expected positions from /usr/bin/python3 with NumPy 1.24.2:
  //   [int(v) for v in np.round(np.linspace(0, L - 1, n))]
  // With all_train = 0..L-1 the picked values are those positions. L = 18, n = 3 and L = 7, n = 5 hit
  // exact halves (8.5 -> 8, 1.5 -> 2, 4.5 -> 4).
  struct Case {
    int length, n;
    std::vector<int> expected;
  };
  const Case cases[] = {
      {17, 1, {0}},
      {17, 2, {0, 16}},
      {17, 3, {0, 8, 16}},
      {17, 4, {0, 5, 11, 16}},
      {17, 6, {0, 3, 6, 10, 13, 16}},
      {17, 12, {0, 1, 3, 4, 6, 7, 9, 10, 12, 13, 15, 16}},
      {18, 3, {0, 8, 17}},
      {18, 5, {0, 4, 8, 13, 17}},
      {18, 9, {0, 2, 4, 6, 8, 11, 13, 15, 17}},
      {7, 5, {0, 2, 3, 4, 6}},
      {7, 6, {0, 1, 2, 4, 5, 6}},
      {35, 3, {0, 17, 34}},
      {35, 8, {0, 5, 10, 15, 19, 24, 29, 34}},
      {35, 24, {0, 1, 3, 4, 6, 7, 9, 10, 12, 13, 15, 16, 18, 19, 21, 22, 24, 25, 27, 28, 30, 31, 33, 34}},
      {36, 12, {0, 3, 6, 10, 13, 16, 19, 22, 25, 29, 32, 35}},
      {100, 5, {0, 25, 50, 74, 99}},
      {100, 24, {0, 4, 9, 13, 17, 22, 26, 30, 34, 39, 43, 47, 52, 56, 60, 65, 69, 73, 77, 82, 86, 90, 95, 99}},
  };
  for (const auto& c : cases) EXPECT_EQ(linspace_pick(iota(c.length), c.n), c.expected) << c.length << " " << c.n;
  // The picks index into all_train, whatever its values.
  EXPECT_EQ(linspace_pick({10, 20, 30, 40, 50, 60, 70}, 5), (std::vector<int>{10, 30, 40, 50, 70}));
  EXPECT_TRUE(linspace_pick(iota(5), 0).empty());
  EXPECT_EQ(linspace_pick(iota(5), 5), iota(5));
  EXPECT_THROW(linspace_pick(iota(5), 6), Error);
  EXPECT_THROW(linspace_pick(iota(5), -1), Error);
}

TEST(Split, FernLikeThreeViews) {
  const auto s = synthetic_scene(20);
  SplitOptions o;
  o.n_views = 3;
  const auto split = make_split(s, o);
  EXPECT_EQ(split.train, (std::vector<int>{1, 10, 19}));
  EXPECT_EQ(split.test, (std::vector<int>{0, 8, 16}));
}

TEST(Split, AllNonTestViewsWhenNViewsIsZero) {
  const auto split = make_split(synthetic_scene(41), {});
  EXPECT_EQ(split.test, (std::vector<int>{0, 8, 16, 24, 32, 40}));
  ASSERT_EQ(split.train.size(), 35u);
  for (int i : split.train) EXPECT_NE(i % 8, 0);
  EXPECT_TRUE(std::is_sorted(split.train.begin(), split.train.end()));
}

TEST(Split, RoomLikeCounts) {
  // 41 images: all_train has 35 entries; 3 views -> all_train[[0, 17, 34]] = [1, 20, 39].
  SplitOptions o;
  o.n_views = 3;
  EXPECT_EQ(make_split(synthetic_scene(41), o).train, (std::vector<int>{1, 20, 39}));
  o.n_views = 35;
  EXPECT_EQ(make_split(synthetic_scene(41), o).train.size(), 35u);
}

TEST(Split, ExplicitListsOverride) {
  const auto s = synthetic_scene(20);
  SplitOptions o;
  o.train_views = {19, 1, 10};
  o.test_views = {2, 3};
  const auto split = make_split(s, o);
  EXPECT_EQ(split.train, (std::vector<int>{1, 10, 19}));
  EXPECT_EQ(split.test, (std::vector<int>{2, 3}));
  // Explicit test views only: the training pool is everything else.
  SplitOptions t;
  t.test_views = {0, 1};
  t.n_views = 2;
  const auto split2 = make_split(s, t);
  EXPECT_EQ(split2.test, (std::vector<int>{0, 1}));
  EXPECT_EQ(split2.train, (std::vector<int>{2, 19}));
}

TEST(Split, ImpossibleRequestsThrow) {
  const auto s = synthetic_scene(20);
  const auto with = [](auto mutate) {
    SplitOptions o;
    mutate(o);
    return o;
  };
  test::expect_error([&] { make_split(s, with([](SplitOptions& o) { o.n_views = 18; })); }, {"18", "17"});
  test::expect_error([&] { make_split(s, with([](SplitOptions& o) { o.n_views = -1; })); }, {"negative"});
  test::expect_error([&] { make_split(s, with([](SplitOptions& o) { o.train_views = {1, 20}; })); },
                     {"--train-views", "20", "out of range"});
  test::expect_error([&] { make_split(s, with([](SplitOptions& o) { o.train_views = {-1}; })); }, {"out of range"});
  test::expect_error([&] { make_split(s, with([](SplitOptions& o) { o.train_views = {3, 3}; })); }, {"twice"});
  test::expect_error([&] { make_split(s, with([](SplitOptions& o) { o.test_views = {4, 5, 4}; })); }, {"twice"});
  test::expect_error([&] { make_split(s, with([](SplitOptions& o) { o.train_views = {1, 8}; })); },
                     {"8", "also a test view"});
  test::expect_error([&] { make_split(s, with([](SplitOptions& o) { o.train_views = {2, 8}, o.test_views = {8}; })); },
                     {"also a test view"});
  test::expect_error([&] { make_split(s, with([](SplitOptions& o) { o.train_views = {1, 2}, o.n_views = 3; })); },
                     {"contradicts"});
  test::expect_error([&] { make_split(synthetic_scene(1), {}); }, {"no training views"});
  test::expect_error([&] { make_split(synthetic_scene(0), {}); }, {"no training views"});
}

TEST(Split, BlenderUsesDatasetSplitAndDietNerfViews) {
  // 100 train frames r_0..r_99 stored in shuffled order, then 3 test frames.
  Scene s;
  s.format = SceneFormat::Blender;
  std::vector<int> order = iota(100);
  std::reverse(order.begin(), order.end());
  for (int k : order) {
    Camera c;
    c.image_name = "r_" + std::to_string(k);
    s.dataset_train.push_back(static_cast<int>(s.cameras.size()));
    s.cameras.push_back(c);
  }
  for (int k : {0, 8, 16}) {
    Camera c;
    c.image_name = "r_" + std::to_string(k);  // test frames reuse the train names
    s.dataset_test.push_back(static_cast<int>(s.cameras.size()));
    s.cameras.push_back(c);
  }
  SplitOptions o;
  o.n_views = 8;
  const auto split = make_split(s, o);
  EXPECT_EQ(split.test, (std::vector<int>{100, 101, 102}));
  ASSERT_EQ(split.train.size(), 8u);
  std::vector<std::string> names;
  for (int i : split.train) {
    EXPECT_LT(i, 100);
    names.push_back(s.cameras[static_cast<std::size_t>(i)].image_name);
  }
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"r_16", "r_2", "r_26", "r_55", "r_73", "r_75", "r_86", "r_93"}));
  // Global index of r_k is 99 - k here: [26, 86, 2, 55, 75, 93, 16, 73] -> sorted [6, 13, 24, 26, 44, 73, 83, 97].
  EXPECT_EQ(split.train, (std::vector<int>{6, 13, 24, 26, 44, 73, 83, 97}));
  // n_views = 0: every dataset train frame.
  EXPECT_EQ(make_split(s, {}).train, iota(100));
  // A missing DietNeRF frame is an error naming it.
  s.cameras[99 - 26].image_name = "r_026";
  test::expect_error([&] { make_split(s, o); }, {"r_26"});
}

}  // namespace
}  // namespace d2gs
