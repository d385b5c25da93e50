#pragma once
// Sparse-view train/test split (method.md §3).
#include <filesystem>
#include <vector>

#include "d2gs/scene/scene.hpp"

namespace d2gs {

struct SplitOptions {
  int n_views = 0;                // training views; 0 = every non-test view
  int test_every = 8;             // LLFF hold-out: index % 8 == 0 is a test view
  std::vector<int> train_views;   // explicit global indices (override n_views when non-empty)
  std::vector<int> test_views;    // explicit global indices (override the hold-out when non-empty)
};

struct Split {
  std::vector<int> train;  // global image indices, ascending
  std::vector<int> test;
};

// Rounds half to even, as NumPy's np.round.
long round_half_even(double x);
// `all_train[round_half_even(linspace(0, len-1, n))]` as the sparse-view papers do.
std::vector<int> linspace_pick(const std::vector<int>& all_train, int n);
// COLMAP/LLFF: test = every 8th image by name; Blender: the dataset's test set, and for 8 views the
// DietNeRF selection [26, 86, 2, 55, 75, 93, 16, 73]. Throws d2gs::Error on impossible requests.
Split make_split(const Scene& scene, const SplitOptions& options);

// A scene (metadata only) and its split: what the commands that work on training or test views start from.
struct SceneAndSplit {
  Scene scene;
  Split split;
};
// load_scene(root, load), then make_split of it.
SceneAndSplit load_scene_and_split(const std::filesystem::path& root, const SceneLoadOptions& load,
                                   const SplitOptions& split);

}  // namespace d2gs
