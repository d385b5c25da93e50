#pragma once
// D²GS presets (method.md §4, §5): the paper's formulas and constants, the authors' released code, and
// the per-scene values the release uses (LLFF 3 views, Mip-NeRF 360 12 views).
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "d2gs/train/config.hpp"

namespace d2gs {

struct D2gsScenePreset {
  const char* dataset;  // "llff" or "mipnerf360"
  const char* scene;
  double weight_depth, weight_density, rate_min, rate_max, mask_percent, dafe_lambda;
};

// The names --preset accepts, in --help's order: paper, release, plus.
const std::vector<std::string>& d2gs_preset_names();

// Every per-scene configuration of the release, in method.md's order.
const std::vector<D2gsScenePreset>& d2gs_scene_presets();

// "paper": Euclidean depth, density carried through densification, w_d = w_ρ = 0.5, r 0.05 → 0.3,
//   far mask 5 %, DAFE loss normalised by the mask area, λ_DAFE = 1.
// "release": depth x·R_w2c[:,2], the release's density cache, w_d 0.3, w_ρ 0.7, r 0.05 → 0.3,
//   DAFE loss averaged over all C·H·W values.
// "plus": the release, plus DropGaussian's compensation per Gaussian (kept opacity ÷ (1 − p_i)) and
//   opacity decay (regulariser "opacity-decay") without the opacity reset; issue 25, docs/training.md.
// Throws d2gs::Error for another name, listing d2gs_preset_names().
void apply_d2gs_preset(TrainConfig& config, const std::string& preset);

// Sets w_d, w_ρ, r_min, r_max, the far-mask percentage and λ_DAFE of a scene: "fern", "llff/fern",
// "mipnerf360/room" (a bare "room" is ambiguous: LLFF and Mip-NeRF 360 both have one). Throws for an
// unknown or ambiguous name, listing the known ones.
void apply_scene_preset(TrainConfig& config, const std::string& name);

// The command line's options (config.json keys) over `config`, which holds the defaults and any
// --config file: first the presets they name (`preset`, then `scene_preset`), then every option given,
// so that an explicit flag wins over a preset, and the names of the presets are recorded. A `preset`
// with a method other than d2gs throws: "plus" would change that method's training (opacity decay,
// no reset) and the others set options it never reads.
void apply_given_options(TrainConfig& config, const nlohmann::json& given);

}  // namespace d2gs
