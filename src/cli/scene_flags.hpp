#pragma once
// The scene and split flags of d2gs info, init and render, declared once:
//   -s,--source  -r,--resolution  --image-source  --white-background  --n-views  [--train-views  --test-views]
// (d2gs train takes them from its option table, train/options.cpp; imr's -s only names the scene of its
// reference camera, and demo's -r and --n-views are those of its own run, with their own defaults.)
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "d2gs/scene/scene.hpp"
#include "d2gs/scene/split.hpp"

namespace d2gs::cli {

struct SceneFlags {
  std::string source;
  int resolution = 1;
  std::string image_source = to_string(kDefaultImageSource);  // "largest" | "folder"
  bool white_background = false;
  int n_views = 0;
  std::vector<int> train_views, test_views;

  SceneLoadOptions load_options() const;
  SplitOptions split_options() const;
  // The scene (metadata only) and its split.
  SceneAndSplit load() const { return load_scene_and_split(source, load_options(), split_options()); }
};

// Which split flags a command takes: --n-views alone, or also the explicit --train-views/--test-views.
enum class SplitFlags { NViews, All };

// Binds -s (required), -r, --image-source, --white-background and the split flags to `flags`, which must outlive `cmd`.
void add_scene_flags(CLI::App& cmd, SceneFlags& flags, SplitFlags split);
// -r alone (d2gs imr).
CLI::Option* add_resolution_flag(CLI::App& cmd, int& resolution);

}  // namespace d2gs::cli
