#include "cli/scene_flags.hpp"

#include "cli/option_checks.hpp"

namespace d2gs::cli {

SceneLoadOptions SceneFlags::load_options() const {
  SceneLoadOptions load;
  load.resolution = resolution;
  load.image_source = image_source_from_string(image_source);
  load.background = glm::vec3(white_background ? 1.0f : 0.0f);
  return load;
}

SplitOptions SceneFlags::split_options() const {
  SplitOptions split;
  split.n_views = n_views;
  split.train_views = train_views;
  split.test_views = test_views;
  return split;
}

CLI::Option* add_resolution_flag(CLI::App& cmd, int& resolution) {
  return add_option(cmd, "-r,--resolution", resolution, "Image resolution 1/R: 1, 2, 4 or 8")->capture_default_str();
}

void add_scene_flags(CLI::App& cmd, SceneFlags& flags, SplitFlags split) {
  add_option(cmd, "-s,--source", flags.source, "Scene folder (COLMAP sparse/0, LLFF poses_bounds.npy or Blender)")
      ->required();
  add_resolution_flag(cmd, flags.resolution);
  add_option(cmd, "--image-source", flags.image_source,
             "Images at -r R: 'largest' (the largest image folder resized with PIL's bicubic, as the original "
             "code and d2gs train do) or 'folder' (the prepared images_R/)")
      ->check(CLI::IsMember({"largest", "folder"}))
      ->capture_default_str();
  add_option(cmd, "--n-views", flags.n_views, "Training views of the sparse-view split (0 = every non-test view)")
      ->capture_default_str();
  if (split == SplitFlags::All) {
    add_option(cmd, "--train-views", flags.train_views, "Explicit training views (global indices, e.g. 1,10,19)")
        ->delimiter(',');
    add_option(cmd, "--test-views", flags.test_views, "Explicit test views (global indices)")->delimiter(',');
  }
  cmd.add_flag("--white-background", flags.white_background,
               "White background: RGBA images composited on white, renders on white (default black)");
}

}  // namespace d2gs::cli
