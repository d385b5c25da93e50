#pragma once
// Training checkpoints (chkpntN.bin, format 3): the whole state of a run after an iteration, so that
// `--resume` continues it bit-identically, and what the run was trained on (scene, resolution, split,
// image names and sizes, every option that changes the training), so that a resume refuses anything else
// with one line naming the checkpoint and the first difference. A CRC-32 over the file finds damage.
// Layout and rules: docs/formats.md, "Checkpoints".
#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "d2gs/core/random.hpp"
#include "d2gs/model/gaussians.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/scene/split.hpp"
#include "d2gs/train/config.hpp"

namespace d2gs {

// Format 3 keeps the training method's state as named groups of arrays (MethodState); format 2, which
// had D²GS's density cache and DAFE masks in fixed places, is still read (into those two groups).
inline constexpr int kCheckpointFormat = 3;

// What a run trains on. A checkpoint continues only a run with an equal identity.
struct RunIdentity {
  std::string scene;                          // the scene folder, absolute and canonical
  std::string scene_format;                   // colmap | llff | blender
  std::string images_folder;                  // the folder the images are read from, e.g. "images_8"
  int resolution = 1;                         // -r
  int scene_images = 0;                       // images in the scene
  std::vector<int> train_views, test_views;   // the split (global indices)
  std::vector<std::string> train_images;      // image names of the training views, in split order
  std::vector<std::array<int, 2>> train_sizes;  // width, height of each training view at -r
  // CRC-32 of each training view's image file (the one decoded for it), in split order: an image whose
  // pixels changed under the same name and size is not the one trained on. Empty in checkpoints written
  // before it was recorded (2026-12-02), which are then not checked for it.
  std::vector<std::uint32_t> train_image_crcs;
  // Each training view's camera, in split order: fx, fy, cx, cy at -r, then the world-to-camera rotation
  // (row-major) and translation. A pose or focal length edited in the scene's files is another run. Empty in
  // checkpoints written before it was recorded (2026-12-03), which are then not checked for it.
  std::vector<std::array<double, 16>> train_cameras;
  // Every option that changes the training (config.json keys; OptionRole::Training in options.hpp), paths
  // made absolute. Left out: those resolved above (source, resolution, n_views, train_views, test_views),
  // --iterations (checked on its own) and the output-only ones (model_path, save/checkpoint/test
  // iterations, log_every, quiet). check_resume compares them under their current names.
  nlohmann::json options = nlohmann::json::object();
};

RunIdentity run_identity(const Scene& scene, const Split& split, const TrainConfig& config);

// The options of `config` that the identity compares (OptionRole::Training), paths made absolute; with
// `also_scene_and_length`, the Scene and Length ones too (the scene folder, -r, the views, --iterations), as
// configured rather than resolved: what two configurations of one run folder must share to be the same run.
nlohmann::json identity_options(const TrainConfig& config, bool also_scene_and_length = false);

// What a training method keeps between iterations (train/methods/method.hpp), by name: groups of float
// arrays and of byte arrays. The checkpoint stores it without knowing what it means; the method checks
// it against the run when resuming.
struct MethodState {
  std::map<std::string, std::vector<std::vector<float>>> floats;
  std::map<std::string, std::vector<std::vector<std::uint8_t>>> bytes;
  bool operator==(const MethodState&) const = default;
};

// The state of a run after iteration `iteration`: everything the next iteration reads.
struct TrainingState {
  int iteration = 0;
  int iterations = 0;  // the run's --iterations when the checkpoint was written
  int active_sh = 0;
  long adam_step = 0;
  double elapsed_s = 0;
  std::vector<int> camera_stack;  // positions in the training views still to visit this epoch
  Rng::State rng_cameras{}, rng_dropout{}, rng_densify{};
  Gaussians model, exp_avg, exp_avg_sq;  // the model and its two Adam moments
  std::vector<float> grad_sums, grad_counts;  // densification statistics, one per Gaussian
  MethodState method;                         // the training method's own state (D²GS: density cache, DAFE masks)
};

struct Checkpoint {
  RunIdentity run;
  TrainingState state;
};

// The file's bytes, and back. decode_checkpoint checks the magic and format, the size, the CRC-32 and
// the shape of every array, and throws d2gs::Error "<source>: <problem>" on the first failure.
std::string encode_checkpoint(const RunIdentity& run, const TrainingState& state);
Checkpoint decode_checkpoint(std::string_view bytes, const std::filesystem::path& source);
// Written atomically.
void write_checkpoint(const std::filesystem::path& path, const RunIdentity& run, const TrainingState& state);
Checkpoint read_checkpoint(const std::filesystem::path& path);

// The chkpntN.bin files in `dir`, highest N first.
std::vector<std::pair<int, std::filesystem::path>> checkpoints_in(const std::filesystem::path& dir);

// Throws d2gs::Error "<source>: cannot resume: <first difference>" unless `checkpoint` continues the run
// `run` trained to `iterations`: equal identities, `iterations` beyond the checkpoint's iteration (or equal
// to it when the checkpoint is the last iteration of a run of that length), and a state that fits the
// run (camera queue, SH degree; the method's state is the method's to check: TrainingMethod::check_state).
// Returns a warning for a resume that is allowed but not an exact
// continuation (another --iterations than the checkpointed run's), else an empty string.
std::string check_resume(const std::filesystem::path& source, const Checkpoint& checkpoint, const RunIdentity& run,
                         int iterations);

}  // namespace d2gs
