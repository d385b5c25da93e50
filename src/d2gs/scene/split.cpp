#include "d2gs/scene/split.hpp"

#include <algorithm>
#include <cmath>
#include <set>
#include <string>

#include "d2gs/core/error.hpp"

namespace d2gs {

namespace {

// DietNeRF's 8 Blender training views: indices of the train frames r_N.
constexpr int kDietNerfViews[] = {26, 86, 2, 55, 75, 93, 16, 73};

void check_indices(const std::vector<int>& indices, std::size_t n, const char* what) {
  std::set<int> seen;
  for (int i : indices) {
    if (i < 0 || static_cast<std::size_t>(i) >= n)
      fail("{}: view {} is out of range (the scene has {} images, 0..{})", what, i, n, n == 0 ? 0 : n - 1);
    if (!seen.insert(i).second) fail("{}: view {} is listed twice", what, i);
  }
}

std::vector<int> sorted(std::vector<int> v) {
  std::sort(v.begin(), v.end());
  return v;
}

}  // namespace

long round_half_even(double x) {
  if (!std::isfinite(x) || std::abs(x) > 9.0e15) fail("round_half_even: {} cannot be rounded to an integer", x);
  const double f = std::floor(x);
  const double diff = x - f;  // exact for |x| < 2^53
  double r = f;
  if (diff > 0.5) r = f + 1;
  else if (diff == 0.5) r = std::fmod(f, 2.0) == 0.0 ? f : f + 1;
  return static_cast<long>(r);
}

std::vector<int> linspace_pick(const std::vector<int>& all_train, int n) {
  if (n < 0) fail("number of views must not be negative, got {}", n);
  if (static_cast<std::size_t>(n) > all_train.size())
    fail("{} views requested but only {} are available", n, all_train.size());
  std::vector<int> out;
  if (n == 0) return out;
  // np.linspace(0, len-1, n): y = i * step with step = (len-1)/(n-1), last = len-1 exactly; n = 1 -> [0].
  const double stop = static_cast<double>(all_train.size() - 1);
  const double step = n > 1 ? stop / (n - 1) : 0.0;
  for (int i = 0; i < n; ++i) {
    const double y = (n > 1 && i == n - 1) ? stop : i * step;
    out.push_back(all_train[static_cast<std::size_t>(round_half_even(y))]);
  }
  return out;
}

Split make_split(const Scene& scene, const SplitOptions& options) {
  const std::size_t n = scene.cameras.size();
  if (options.n_views < 0) fail("--n-views must not be negative, got {}", options.n_views);
  if (options.test_every < 1) fail("test_every must be at least 1, got {}", options.test_every);
  const bool blender = scene.format == SceneFormat::Blender;

  Split split;
  // ---- test views
  if (!options.test_views.empty()) {
    check_indices(options.test_views, n, "--test-views");
    split.test = sorted(options.test_views);
  } else if (blender) {
    split.test = sorted(scene.dataset_test);
  } else {
    for (std::size_t i = 0; i < n; i += static_cast<std::size_t>(options.test_every)) split.test.push_back(static_cast<int>(i));
  }
  const std::set<int> test(split.test.begin(), split.test.end());

  // ---- training views
  if (!options.train_views.empty()) {
    check_indices(options.train_views, n, "--train-views");
    for (int i : options.train_views)
      if (test.count(i)) fail("--train-views: view {} is also a test view", i);
    split.train = sorted(options.train_views);
    if (options.n_views != 0 && static_cast<std::size_t>(options.n_views) != split.train.size())
      fail("--n-views {} contradicts the {} views of --train-views", options.n_views, split.train.size());
    return split;
  }
  std::vector<int> pool;  // candidate training views, ascending
  if (blender) {
    for (int i : sorted(scene.dataset_train))
      if (!test.count(i)) pool.push_back(i);
  } else {
    for (std::size_t i = 0; i < n; ++i)
      if (!test.count(static_cast<int>(i))) pool.push_back(static_cast<int>(i));
  }
  if (pool.empty()) fail("no training views left: every image is a test view");
  if (static_cast<std::size_t>(options.n_views) > pool.size())
    fail("--n-views {}: only {} training views are available", options.n_views, pool.size());

  if (options.n_views == 0) {
    split.train = pool;
  } else if (blender && options.n_views == 8) {
    // DietNeRF's selection, by frame name among the dataset's training frames.
    for (int k : kDietNerfViews) {
      const std::string name = "r_" + std::to_string(k);
      const auto it = std::find_if(pool.begin(), pool.end(), [&](int i) {
        return scene.cameras[static_cast<std::size_t>(i)].image_name == name;
      });
      if (it == pool.end())
        fail("{}: the 8-view Blender split needs train frame {}, which the scene does not have", scene.root.string(), name);
      split.train.push_back(*it);
    }
    split.train = sorted(split.train);
  } else {
    split.train = linspace_pick(pool, options.n_views);
  }
  return split;
}

SceneAndSplit load_scene_and_split(const std::filesystem::path& root, const SceneLoadOptions& load,
                                   const SplitOptions& split) {
  SceneAndSplit out;
  out.scene = load_scene(root, load);
  out.split = make_split(out.scene, split);
  return out;
}

}  // namespace d2gs
