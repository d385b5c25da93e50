#include "d2gs/train/options.hpp"

#include <algorithm>
#include <cmath>
#include <optional>
#include <type_traits>
#include <utility>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "d2gs/core/error.hpp"
#include "d2gs/core/json_value.hpp"
#include "d2gs/core/number_word.hpp"
#include "d2gs/train/config.hpp"
#include "d2gs/train/methods/registry.hpp"
#include "d2gs/train/presets.hpp"

namespace d2gs {
namespace {

using json = nlohmann::json;

// What every declaration has.
struct Spec {
  const char* name;
  const char* group;
  const char* help;
  OptionRole role = OptionRole::Training;
  const char* short_flag = "";
  std::vector<std::string> aliases = {};
};

// The range of a number option (or of each number of a list). Values compare as doubles, exact for
// every bound used here.
struct Bounds {
  std::optional<double> min = {}, max = {};
  bool min_open = false, max_open = false;
  std::vector<double> allowed = {};  // when not empty: only these
  std::string shown = {};            // the range as --help words it, when not the generated one

  bool contains(double v) const {
    if (!allowed.empty()) return std::find(allowed.begin(), allowed.end(), v) != allowed.end();
    if (min && (min_open ? !(v > *min) : !(v >= *min))) return false;
    if (max && (max_open ? !(v < *max) : !(v <= *max))) return false;
    return true;
  }
  std::string text() const {
    if (!shown.empty()) return shown;
    if (!allowed.empty()) {
      std::string s;
      for (std::size_t i = 0; i < allowed.size(); ++i)
        s += fmt::format("{}{}", i == 0 ? "" : i + 1 == allowed.size() ? " or " : ", ", allowed[i]);
      return s;
    }
    if (min && max) return fmt::format("{}{}, {}{}", min_open ? "(" : "[", *min, *max, max_open ? ")" : "]");
    if (min) return fmt::format("{} {}", min_open ? ">" : "≥", *min);
    if (max) return fmt::format("{} {}", max_open ? "<" : "≤", *max);
    return {};
  }
  // As in "must be ...".
  std::string phrase() const {
    const std::string t = text();
    return allowed.empty() && shown.empty() && min && max ? "in " + t : t;
  }
};

Bounds any_value() { return {}; }
Bounds positive() { return {.min = 0.0, .min_open = true}; }
Bounds at_least(double v) { return {.min = v}; }
Bounds closed(double a, double b) { return {.min = a, .max = b}; }
Bounds half_open(double a, double b) { return {.min = a, .max = b, .max_open = true}; }
Bounds one_of(std::vector<double> values) { return {.allowed = std::move(values)}; }

// The field an accessor returns, for a TrainConfig.
template <typename Field>
using FieldType = std::remove_cvref_t<decltype(std::declval<Field>()(std::declval<TrainConfig&>()))>;

TrainOption base(const Spec& s, OptionKind kind, std::string type_name, std::string range) {
  TrainOption o;
  o.name = s.name;
  o.aliases = s.aliases;
  o.short_flag = s.short_flag;
  o.group = s.group;
  o.help = s.help;
  o.kind = kind;
  o.role = s.role;
  o.type_name = std::move(type_name);
  o.range = std::move(range);
  return o;
}

[[noreturn]] void wrong_type(const std::string& name, const char* expected, const json& v) {
  fail("key '{}' has the wrong type (expected {}, got {})", name, expected, v.type_name());
}

const std::string& one_word(const std::vector<std::string>& words, const std::string& flag_name) {
  if (words.size() != 1) fail("option {} takes one value (got {})", flag_name, words.size());
  return words.front();
}

// A command-line word as a number of type T (core/number_word.hpp: all of it, no sign on an unsigned type).
template <typename T>
T number_word(const std::string& word, const std::string& flag_name) {
  T value{};
  if (const std::string problem = number_word_problem(word, value); !problem.empty())
    fail("option {}: {}", flag_name, problem);
  return value;
}

template <typename Field>
TrainOption flag(const Spec& s, Field field) {
  TrainOption o = base(s, OptionKind::Flag, "", "");
  o.get = [field](const TrainConfig& c) { return json(field(c)); };
  o.set = [field, name = o.name](TrainConfig& c, const json& v) {
    if (!v.is_boolean()) wrong_type(name, "boolean", v);
    field(c) = v.get<bool>();
  };
  o.check = [](const TrainConfig&) {};
  o.parse = [flag_name = o.flag()](const std::vector<std::string>& words) {
    const std::string& w = one_word(words, flag_name);
    if (w != "true" && w != "false") fail("option {}: '{}' is not true or false", flag_name, w);
    return json(w == "true");
  };
  o.default_text = [field]() {
    TrainConfig d;
    return std::string(field(d) ? "on" : "off");
  };
  return o;
}

template <typename Field>
TrainOption number(const Spec& s, Field field, Bounds bounds) {
  using T = FieldType<Field>;
  static_assert(std::is_arithmetic_v<T> && !std::is_same_v<T, bool>);
  constexpr bool integral = std::is_integral_v<T>;
  TrainOption o = base(s, integral ? OptionKind::Integer : OptionKind::Real, integral ? "INT" : "FLOAT", bounds.text());
  o.get = [field](const TrainConfig& c) { return json(field(c)); };
  o.set = [field, name = o.name](TrainConfig& c, const json& v) { field(c) = json_number<T>(v, name); };
  o.check = [field, bounds, flag_name = o.flag()](const TrainConfig& c) {
    const T v = field(c);
    if (!bounds.contains(static_cast<double>(v))) fail("option {} must be {} (got {})", flag_name, bounds.phrase(), v);
  };
  o.parse = [flag_name = o.flag()](const std::vector<std::string>& words) {
    return json(number_word<T>(one_word(words, flag_name), flag_name));
  };
  o.default_text = [field]() {
    TrainConfig d;
    return fmt::format("{}", field(d));
  };
  return o;
}

template <typename Field>
TrainOption integer_list(const Spec& s, Field field, Bounds each) {
  TrainOption o = base(s, OptionKind::IntegerList, "INT", each.text().empty() ? "" : "each " + each.text());
  o.get = [field](const TrainConfig& c) { return json(field(c)); };
  o.set = [field, name = o.name](TrainConfig& c, const json& v) { field(c) = json_number_list<int>(v, name); };
  o.check = [field, each, flag_name = o.flag()](const TrainConfig& c) {
    for (int v : field(c))
      if (!each.contains(v)) fail("option {}: every value must be {} (got {})", flag_name, each.phrase(), v);
  };
  o.parse = [flag_name = o.flag()](const std::vector<std::string>& words) {
    json list = json::array();  // "none": the empty list
    for (const auto& w : words)
      if (w != "none") list.push_back(number_word<int>(w, flag_name));
    return list;
  };
  o.default_text = [field]() {
    TrainConfig d;
    return field(d).empty() ? std::string("none") : fmt::format("{}", fmt::join(field(d), ","));
  };
  return o;
}

// A string: free text, or a path that may also be one of `keywords`.
template <typename Field>
TrainOption text(const Spec& s, Field field, OptionKind kind = OptionKind::Text, std::vector<std::string> keywords = {}) {
  TrainOption o = base(s, kind, kind == OptionKind::Path ? "PATH" : "TEXT", "");
  o.keywords = std::move(keywords);
  o.get = [field](const TrainConfig& c) { return json(field(c)); };
  o.set = [field, name = o.name](TrainConfig& c, const json& v) {
    if (!v.is_string()) wrong_type(name, "string", v);
    field(c) = v.get<std::string>();
  };
  o.check = [](const TrainConfig&) {};
  o.parse = [flag_name = o.flag()](const std::vector<std::string>& words) { return json(one_word(words, flag_name)); };
  o.default_text = [field]() {
    TrainConfig d;
    const std::string v = field(d);
    return v.empty() ? std::string("none") : v;
  };
  return o;
}

// --preset's words: none (the defaults) or one of presets.hpp's names.
std::vector<std::pair<std::string, std::string>> preset_choices() {
  std::vector<std::pair<std::string, std::string>> names = {{"", ""}};
  for (const std::string& n : d2gs_preset_names()) names.emplace_back(n, n);
  return names;
}

// One of a few names, each standing for a value of the field (an enum, a bool or a string).
template <typename Field>
TrainOption choice(const Spec& s, Field field, std::vector<std::pair<std::string, FieldType<Field>>> names) {
  std::vector<std::string> words;
  for (const auto& n : names)
    if (!n.first.empty()) words.push_back(n.first);
  const std::string list = fmt::format("{}", fmt::join(words, ", "));
  TrainOption o = base(s, OptionKind::Choice, fmt::format("{}", fmt::join(words, "|")), "");
  for (const auto& n : names) o.choices.push_back(n.first);
  o.get = [field, names](const TrainConfig& c) {
    const auto& v = field(c);
    for (const auto& [name, value] : names)
      if (value == v) return json(name);
    return json(nullptr);
  };
  o.set = [field, names, list, name = o.name](TrainConfig& c, const json& v) {
    if (!v.is_string()) wrong_type(name, "string", v);
    for (const auto& [word, value] : names)
      if (v.get<std::string>() == word) {
        field(c) = value;
        return;
      }
    fail("key '{}': '{}' is not one of {}", name, v.get<std::string>(), list);
  };
  // A value set in code (not read through set()) must be one of the names too.
  o.check = [field, names, list, flag_name = o.flag()](const TrainConfig& c) {
    const auto& v = field(c);
    for (const auto& n : names)
      if (n.second == v) return;
    if constexpr (std::is_same_v<FieldType<Field>, std::string>)
      fail("option {} must be one of {} (got '{}')", flag_name, list, v);
    else
      fail("option {} must be one of {}", flag_name, list);
  };
  o.parse = [flag_name = o.flag(), names, list](const std::vector<std::string>& words_given) {
    const std::string& w = one_word(words_given, flag_name);
    for (const auto& n : names)
      if (n.first == w) return json(w);
    fail("option {}: '{}' is not one of {}", flag_name, w, list);
  };
  o.default_text = [field, names]() {
    TrainConfig d;
    for (const auto& [name, value] : names)
      if (value == field(d)) return name.empty() ? std::string("none") : name;
    return std::string("?");
  };
  return o;
}

// A list of distinct names, each one of `words` (comma-separated on the command line; "none": empty).
template <typename Field>
TrainOption name_list(const Spec& s, Field field, std::vector<std::string> words) {
  const std::string list = fmt::format("{}", fmt::join(words, ", "));
  TrainOption o = base(s, OptionKind::NameList, fmt::format("{}", fmt::join(words, ",")), "");
  o.choices = words;
  o.get = [field](const TrainConfig& c) { return json(field(c)); };
  // One check for set() and for values set in code: every name known, none twice.
  const auto check_names = [words, list](const std::vector<std::string>& names, const std::string& what) {
    for (std::size_t i = 0; i < names.size(); ++i) {
      if (std::find(words.begin(), words.end(), names[i]) == words.end())
        fail("{}: '{}' is not one of {}", what, names[i], list);
      if (std::find(names.begin(), names.begin() + static_cast<std::ptrdiff_t>(i), names[i]) != names.begin() + static_cast<std::ptrdiff_t>(i))
        fail("{}: '{}' is named twice", what, names[i]);
    }
  };
  o.set = [field, check_names, name = o.name](TrainConfig& c, const json& v) {
    if (!v.is_array()) wrong_type(name, "list of names", v);
    std::vector<std::string> names;
    for (const json& e : v) {
      if (!e.is_string()) wrong_type(name, "list of names", v);
      names.push_back(e.get<std::string>());
    }
    check_names(names, fmt::format("key '{}'", name));
    field(c) = std::move(names);
  };
  o.check = [field, check_names, flag_name = o.flag()](const TrainConfig& c) {
    check_names(field(c), fmt::format("option {}", flag_name));
  };
  o.parse = [flag_name = o.flag(), check_names](const std::vector<std::string>& given) {
    std::vector<std::string> names;
    for (const auto& w : given)
      if (w != "none") names.push_back(w);
    check_names(names, fmt::format("option {}", flag_name));
    return json(names);
  };
  o.default_text = [field]() {
    TrainConfig d;
    return field(d).empty() ? std::string("none") : fmt::format("{}", fmt::join(field(d), ","));
  };
  return o;
}

std::vector<TrainOption> declare() {
  using enum OptionRole;
  using enum OptionKind;
  const char* const scene = "Scene and split";
  const char* const method = "Method";
  const char* const init = "Initial points";
  const char* const optimisation = "Optimisation";
  const char* const densification = "Densification";
  const char* const dropgaussian = "DropGaussian";
  const char* const dd_drop = "D²GS: presets and DD-Drop";
  const char* const dafe = "D²GS: DAFE";
  const char* const regularisers = "Regularisers (any method)";
  const char* const outputs = "Outputs";
  std::vector<TrainOption> t;
  // ---- scene and split ----
  t.push_back(text({"source", scene, "Scene folder (COLMAP, LLFF or Blender); required", Scene, "-s"},
                   [](auto& c) -> auto& { return c.source; }, Path));
  t.push_back(text({"model_path", scene, "Output folder of the run; required", Output, "-m", {"model_dir"}},
                   [](auto& c) -> auto& { return c.model_dir; }, Path));
  t.push_back(number({"resolution", scene, "1/R of full resolution", Scene, "-r"},
                     [](auto& c) -> auto& { return c.resolution; }, one_of({1, 2, 4, 8})));
  t.push_back(number({"n_views", scene, "Training views of the sparse-view split (0 = all non-test views)", Scene},
                     [](auto& c) -> auto& { return c.n_views; }, at_least(0)));
  t.push_back(integer_list({"train_views", scene, "Explicit training views (global indices)", Scene},
                           [](auto& c) -> auto& { return c.train_views; }, at_least(0)));
  t.push_back(integer_list({"test_views", scene, "Explicit test views (global indices)", Scene},
                           [](auto& c) -> auto& { return c.test_views; }, at_least(0)));
  t.push_back(flag({"white_background", scene, "White background (Blender scenes)"},
                   [](auto& c) -> auto& { return c.white_background; }));
  t.push_back(choice({"image_source", scene,
                      "Images at -r R: 'largest' (the largest image folder, resized with PIL's bicubic as "
                      "the original code does; training and ground truth, so that PSNR is measured on the papers' "
                      "pixels) or 'folder' (the prepared images_R/, else a larger folder area-resampled)"},
                     [](auto& c) -> auto& { return c.image_source; },
                     {{"folder", ImageSource::Folder}, {"largest", ImageSource::Largest}}));
  t.back().absent_means = "folder";  // the default until issue 23 (2026-11-27)
  // ---- method ----
  {
    // The methods of the registry (train/methods/registry.cpp), each with its help.
    std::vector<std::pair<std::string, std::string>> names;
    std::string help = "Training method:";
    for (const MethodInfo& m : training_methods()) {
      names.emplace_back(m.name, m.name);
      help += fmt::format("{} '{}' ({})", names.size() == 1 ? "" : ",", m.name, m.help);
    }
    t.push_back(choice({"method", method, help.c_str()}, [](auto& c) -> auto& { return c.method; }, std::move(names)));
  }
  t.push_back(number({"iterations", method, "Training iterations", Length},
                     [](auto& c) -> auto& { return c.iterations; }, positive()));
  t.push_back(number({"seed", method, "Seed of every random choice (same seed and input: same model)"},
                     [](auto& c) -> auto& { return c.seed; }, any_value()));
  t.push_back(choice({"device", method,
                      "Backend: 'cpu' (the reference), 'cuda' (an error where no CUDA device or no complete CUDA "
                      "backend exists), 'auto' (CUDA when both exist, else the CPU, saying why; `d2gs info` shows the "
                      "choice), 'emulated' (the CUDA kernels run on the CPU by the emulator instead of a GPU: slow, for "
                      "checking them)",
                      Output},
                     [](auto& c) -> auto& { return c.device; },
                     {{"cpu", render::DeviceRequest::Cpu},
                      {"cuda", render::DeviceRequest::Cuda},
                      {"auto", render::DeviceRequest::Auto},
                      {"emulated", render::DeviceRequest::Emulated}}));
  // ---- initial points ----
  t.push_back(text({"init", init,
                    "Initial points: 'dense' (stereo depth of the training views fused, as `d2gs init`; reuses "
                    "SCENE/{N}_views or MODEL/init), 'sparse' (SIFT points triangulated from the training views), a "
                    "PLY file, 'random', or 'sfm-all-views' (the dataset's points3D: an ORACLE, it saw the test views)"},
                   [](auto& c) -> auto& { return c.init; }, Path, {"dense", "sparse", "random", "sfm-all-views"}));
  t.push_back(choice({"init_dense_method", init,
                      "Stereo of --init dense (and of --dafe-prior stereo): 'patchmatch' (PatchMatch multi-view "
                      "stereo at the highest resolution of the scene folder, as `d2gs init`) or 'sgbm' (rectified "
                      "SGBM at the training resolution, as `d2gs init --dense-method sgbm`)"},
                     [](auto& c) -> auto& { return c.init_dense_method; },
                     {{"sgbm", "sgbm"}, {"patchmatch", "patchmatch"}}));
  t.push_back(number({"init_color_filter", init,
                      "PatchMatch fusion of --init dense: drop a fused point whose colour differs from a training "
                      "image (blurred) by more than this mean absolute RGB difference where no surface hides it: "
                      "mid-air points seen through to another colour (0: off; SGBM ignores it; as `d2gs init "
                      "--fusion-max-color-difference`; docs/training.md)"},
                     [](auto& c) -> auto& { return c.init_color_filter; }, closed(0.0, 1.0)));
  t.back().absent_means = 0.0;  // added off (2ce5087), on by default since 6ffbd09
  t.push_back(number({"init_pm_distinctiveness", init,
                      "PatchMatch of --init dense: keep a depth only where a confirming source's cost (1 - NCC) rises "
                      "by at least this much when the match moves a window radius along its epipolar line: drops "
                      "depths the images do not determine (0: off; as `d2gs init --pm-filter-min-distinctiveness`; "
                      "docs/training.md)"},
                     [](auto& c) -> auto& { return c.init_pm_distinctiveness; }, closed(0.0, 2.0)));
  t.push_back(number({"init_pm_uniqueness", init,
                      "PatchMatch of --init dense: keep a depth only where a confirming source's match beats every "
                      "other match on its epipolar line (more than two window radii away) by at least this much in "
                      "1 - NCC: drops depths that repeated patterns, reflections or uniform regions leave ambiguous "
                      "(0: off; as `d2gs init --pm-filter-min-uniqueness`; docs/training.md)"},
                     [](auto& c) -> auto& { return c.init_pm_uniqueness; }, closed(0.0, 2.0)));
  t.back().absent_means = 0.0;  // runs recorded before the option existed trained without the test (on since issue 22)
  t.push_back(number({"init_pm_uniqueness_step", init,
                      "PatchMatch of --init dense: the uniqueness test samples the epipolar line every this many "
                      "window radii; finer finds narrower rival matches, at more stereo time (as `d2gs init "
                      "--pm-filter-uniqueness-step`; docs/training.md)"},
                     [](auto& c) -> auto& { return c.init_pm_uniqueness_step; }, closed(0.05, 4.0)));
  t.back().absent_means = 1.0;  // runs recorded before the option existed sampled every window radius
  t.push_back(number({"random_points", init,
                      "Point count of --init random (random pixel rays of the training views, uniform inverse depth "
                      "within the scene's depth bounds: docs/training.md); at most 10 million, whose training "
                      "state alone is about 10 GB (3DGS starts Blender scenes from 100 000)"},
                     [](auto& c) -> auto& { return c.random_points; }, closed(1, 1e7)));
  // ---- optimisation ----
  t.push_back(number({"position_lr", optimisation, "Initial position learning rate (× scene extent)"},
                     [](auto& c) -> auto& { return c.lr.means; }, positive()));
  t.push_back(number({"position_lr_final", optimisation, "Final position learning rate (× scene extent)"},
                     [](auto& c) -> auto& { return c.position_lr_final; }, positive()));
  t.push_back(number({"sh_dc_lr", optimisation, "SH DC learning rate"}, [](auto& c) -> auto& { return c.lr.sh_dc; },
                     positive()));
  t.push_back(number({"sh_rest_lr", optimisation, "SH rest learning rate"},
                     [](auto& c) -> auto& { return c.lr.sh_rest; }, positive()));
  t.push_back(number({"opacity_lr", optimisation, "Opacity learning rate"},
                     [](auto& c) -> auto& { return c.lr.opacity; }, positive()));
  t.push_back(number({"scaling_lr", optimisation, "Scale learning rate"}, [](auto& c) -> auto& { return c.lr.scales; },
                     positive()));
  t.push_back(number({"rotation_lr", optimisation, "Rotation learning rate"},
                     [](auto& c) -> auto& { return c.lr.quats; }, positive()));
  t.push_back(number({"lambda_dssim", optimisation, "Weight of 1 − SSIM in the loss"},
                     [](auto& c) -> auto& { return c.lambda_dssim; }, closed(0, 1)));
  t.push_back(choice({"alpha_clamp_grad", optimisation,
                      "Gradient through alpha = min(0.99, o·G): 'exact' (0 where clamped) or 'pass-through' (as if "
                      "unclamped: the original rasterizer's rule)"},
                     [](auto& c) -> auto& { return c.alpha_clamp_pass_through; },
                     {{"exact", false}, {"pass-through", true}}));
  t.push_back(number({"sh_degree", optimisation, "Maximum SH degree"}, [](auto& c) -> auto& { return c.sh_degree; },
                     closed(0, 3)));
  t.push_back(number({"sh_increase_every", optimisation, "Iterations between raises of the active SH degree"},
                     [](auto& c) -> auto& { return c.sh_increase_every; }, positive()));
  // ---- densification ----
  t.push_back(number({"densify_grad_threshold", densification, "Screen-space gradient threshold (NDC units)"},
                     [](auto& c) -> auto& { return c.densify.grad_threshold; }, positive()));
  t.push_back(number({"percent_dense", densification,
                      "Clone a Gaussian whose largest scale is at most this fraction of the scene extent, else split"},
                     [](auto& c) -> auto& { return c.densify.percent_dense; }, at_least(0)));
  t.push_back(number({"min_opacity", densification, "Prune Gaussians whose opacity is below this"},
                     [](auto& c) -> auto& { return c.densify.min_opacity; }, half_open(0, 1)));
  t.push_back(number({"densify_from", densification, "Densify after this iteration"},
                     [](auto& c) -> auto& { return c.densify_from; }, at_least(0)));
  t.push_back(number({"densify_until", densification, "Densify before this iteration"},
                     [](auto& c) -> auto& { return c.densify_until; }, at_least(0)));
  t.push_back(number({"densify_every", densification, "Densification interval"},
                     [](auto& c) -> auto& { return c.densify_every; }, positive()));
  t.push_back(integer_list({"opacity_reset_at", densification, "Iterations of the opacity reset"},
                           [](auto& c) -> auto& { return c.opacity_reset_at; }, at_least(1)));
  // ---- DropGaussian ----
  t.push_back(number({"dropgaussian_max_rate", dropgaussian, "DropGaussian: final drop rate (r = max·t/T)", Training, "",
                      {"drop_rate"}},
                     [](auto& c) -> auto& { return c.dropgaussian_max_rate; }, half_open(0, 1)));
  // ---- D²GS ----
  t.push_back(choice({"preset", dd_drop,
                      "D²GS preset, with --method d2gs only: 'paper' (the paper's formulas and constants) or 'release' (the authors' code, "
                      "quirks included; its values are the defaults, chosen by measurement: docs/training.md) or 'plus' "
                      "(the release with compensation per Gaussian and opacity decay in place of the opacity reset); "
                      "applied over --config, and flags override it"},
                     [](auto& c) -> auto& { return c.preset; },
                     preset_choices()));
  t.push_back(text({"scene_preset", dd_drop,
                    "D²GS per-scene values of the release, e.g. fern, llff/room, mipnerf360/bicycle (weights, rates, "
                    "far-mask %, DAFE weight); applied after --preset"},
                   [](auto& c) -> auto& { return c.scene_preset; }));
  t.push_back(number({"dd_weight_depth", dd_drop, "Weight w_d of the depth score"},
                     [](auto& c) -> auto& { return c.dd_drop.weight_depth; }, at_least(0)));
  t.push_back(number({"dd_weight_density", dd_drop, "Weight w_ρ of the density score"},
                     [](auto& c) -> auto& { return c.dd_drop.weight_density; }, at_least(0)));
  t.push_back(number({"dd_rate_min", dd_drop, "Initial drop rate r_min (at most --dd-rate-max)"},
                     [](auto& c) -> auto& { return c.dd_drop.rate_min; }, closed(0, 1)));
  t.push_back(number({"dd_rate_max", dd_drop, "Final drop rate r_max"},
                     [](auto& c) -> auto& { return c.dd_drop.rate_max; }, closed(0, 1)));
  t.push_back(number({"dd_rate_iterations", dd_drop, "Iterations T over which the drop rate rises"},
                     [](auto& c) -> auto& { return c.dd_drop.rate_iterations; }, positive()));
  t.push_back(flag({"dd_use_depth_score", dd_drop, "Use the depth score (ablation switch)"},
                   [](auto& c) -> auto& { return c.dd_drop.use_depth_score; }));
  t.push_back(flag({"dd_use_density_score", dd_drop, "Use the density score (ablation switch)"},
                   [](auto& c) -> auto& { return c.dd_drop.use_density_score; }));
  t.push_back(flag({"dd_use_layers", dd_drop, "Scale by the depth layer's λ (ablation switch)"},
                   [](auto& c) -> auto& { return c.dd_drop.use_layers; }));
  t.push_back(number({"dd_lambda_near", dd_drop, "λ of the near depth layer"},
                     [](auto& c) -> auto& { return c.dd_drop.lambda_near; }, at_least(0)));
  t.push_back(number({"dd_lambda_middle", dd_drop, "λ of the middle depth layer"},
                     [](auto& c) -> auto& { return c.dd_drop.lambda_middle; }, at_least(0)));
  t.push_back(number({"dd_lambda_far", dd_drop, "λ of the far depth layer"},
                     [](auto& c) -> auto& { return c.dd_drop.lambda_far; }, at_least(0)));
  t.push_back(choice({"dd_depth_mode", dd_drop,
                      "Depth of a Gaussian: 'euclidean' (distance to the camera centre: paper) or 'release-dot' "
                      "(x·R_w2c[:,2]: release)"},
                     [](auto& c) -> auto& { return c.dd_drop.depth_mode; },
                     {{"euclidean", DepthMode::Euclidean}, {"release-dot", DepthMode::ReleaseDot}}));
  t.push_back(flag({"dd_compensate", dd_drop,
                    "Scale kept Gaussians' opacity by 1/(1 − p_i) as DropGaussian does (a diagnostic; paper and "
                    "release: off)"},
                   [](auto& c) -> auto& { return c.dd_drop.compensate; }));
  t.push_back(number({"density_refresh_every", dd_drop, "Iterations between recomputations of the density scores"},
                     [](auto& c) -> auto& { return c.dd_drop.density_refresh_every; }, positive()));
  t.push_back(flag({"release_density_cache", dd_drop,
                    "The release's density cache through densification (scores 0.5 after growth, the first N after "
                    "pruning) instead of carrying each score to the Gaussian's children"},
                   [](auto& c) -> auto& { return c.dd_drop.release_density_cache; }));
  t.push_back(flag({"dafe", dafe, "Distance-aware fidelity enhancement: an L1 term on the far region"},
                   [](auto& c) -> auto& { return c.dafe.enabled; }));
  t.push_back(text({"dafe_prior", dafe,
                    "Folder of per-view prior maps NAME.npy, or 'stereo' (the depth maps of `d2gs init`, kind "
                    "depth); none: the model's own depth at iteration 1000",
                    Training, "", {"dafe_prior_dir"}},
                   [](auto& c) -> auto& { return c.dafe.prior; }, Path, {"", "stereo"}));
  t.push_back(choice({"dafe_prior_kind", dafe,
                      "The --dafe-prior maps hold 'disparity' (large = near) or 'depth' (0 = no value)"},
                     [](auto& c) -> auto& { return c.dafe.prior_kind; },
                     {{"depth", PriorKind::Depth}, {"disparity", PriorKind::Disparity}}));
  t.push_back(choice({"dafe_mask_rule", dafe,
                      "Far region: 'percentile' (the farthest --dafe-tau % of the pixels) or 'threshold' (depth "
                      "above --dafe-tau × the largest depth: the paper's equation)"},
                     [](auto& c) -> auto& { return c.dafe.mask_rule; },
                     {{"percentile", DafeMaskRule::Percentile}, {"threshold", DafeMaskRule::Threshold}}));
  {
    Bounds tau = closed(0, 100);
    tau.shown = "[0, 100] (percentile rule), [0, 1] (threshold rule)";
    TrainOption o = number({"dafe_tau", dafe, "Far-mask percentage (percentile rule) or fraction (threshold rule)"},
                           [](auto& c) -> auto& { return c.dafe.tau; }, tau);
    o.check = [flag_name = o.flag()](const TrainConfig& c) {
      const double v = c.dafe.tau;
      if (c.dafe.mask_rule == DafeMaskRule::Percentile && !(v >= 0 && v <= 100))
        fail("option {} must be a percentage in [0, 100] for the percentile rule (got {})", flag_name, v);
      if (c.dafe.mask_rule == DafeMaskRule::Threshold && !(v >= 0 && v <= 1))
        fail("option {} must be a fraction in [0, 1] for the threshold rule (got {})", flag_name, v);
    };
    t.push_back(std::move(o));
  }
  t.push_back(choice({"dafe_loss_form", dafe,
                      "'paper' (L1 over the mask normalised by its area) or 'release' (averaged over all C·H·W "
                      "values)"},
                     [](auto& c) -> auto& { return c.dafe.loss_form; },
                     {{"paper", DafeLossForm::Paper}, {"release", DafeLossForm::Release}}));
  t.push_back(number({"dafe_lambda", dafe, "DAFE loss weight"}, [](auto& c) -> auto& { return c.dafe.lambda; },
                     at_least(0)));
  // ---- regularisers (train/methods/registry.cpp) ----
  {
    std::vector<std::string> names;
    std::string help = "Regularisers stacked on the method, comma-separated, in this order:";
    for (const MethodInfo& r : training_regularisers()) {
      names.emplace_back(r.name);
      help += fmt::format("{} '{}' ({})", names.size() == 1 ? "" : ",", r.name, r.help);
    }
    t.push_back(name_list({"regularisers", regularisers, help.c_str()}, [](auto& c) -> auto& { return c.regularisers; },
                          std::move(names)));
  }
  t.push_back(number({"opacity_noise_sigma", regularisers,
                      "opacity-noise: σ of ε in o·(1 + ε), ε ~ N(0, σ²) clipped to [−σ, σ]"},
                     [](auto& c) -> auto& { return c.opacity_noise_sigma; }, half_open(0, 1)));
  t.push_back(number({"opacity_decay_factor", regularisers,
                      "opacity-decay: each Gaussian's opacity times this after every iteration past --densify-from"},
                     [](auto& c) -> auto& { return c.opacity_decay_factor; }, {.min = 0.0, .max = 1.0, .min_open = true}));
  t.push_back(number({"stereo_depth_lambda", regularisers,
                      "stereo-depth: weight of the relative disparity L1 between the render and the training views' "
                      "stereo depth"},
                     [](auto& c) -> auto& { return c.stereo_depth_lambda; }, at_least(0)));
  t.push_back(number({"anisotropy_ratio", regularisers,
                      "anisotropy: the axis ratio s_max / s_min beyond which a Gaussian is penalised"},
                     [](auto& c) -> auto& { return c.anisotropy_ratio; }, {.min = 1.0}));
  t.push_back(number({"anisotropy_lambda", regularisers,
                      "anisotropy: weight of mean max(0, ln(s_max / s_min) − ln ratio) over the Gaussians"},
                     [](auto& c) -> auto& { return c.anisotropy_lambda; }, at_least(0)));
  t.push_back(number({"scale_l1_lambda", regularisers,
                      "scale-l1: weight of the mean of the Gaussians' scales (all three axes)"},
                     [](auto& c) -> auto& { return c.scale_l1_lambda; }, at_least(0)));
  // ---- outputs ----
  t.push_back(integer_list({"save_iterations", outputs, "Iterations whose model is saved (default: the last)", Output},
                           [](auto& c) -> auto& { return c.save_iterations; }, closed(1, 2147483647)));
  t.push_back(integer_list({"checkpoint_iterations", outputs,
                            "Iterations whose full training state is saved (chkpntN.bin)", Output},
                           [](auto& c) -> auto& { return c.checkpoint_iterations; }, closed(1, 2147483647)));
  t.push_back(integer_list({"test_iterations", outputs, "Iterations at which test PSNR/SSIM are logged", Output},
                           [](auto& c) -> auto& { return c.test_iterations; }, closed(1, 2147483647)));
  t.push_back(number({"stop_at", outputs,
                      "Stop after this iteration of the --iterations schedule (0 = train to the end): the full "
                      "training state is saved as chkpntN.bin and the test views scored, as at a "
                      "--test-iterations entry; --resume chkpntN.bin continues the same run. For short proxy runs "
                      "and for splitting a long run",
                      Output},
                     [](auto& c) -> auto& { return c.stop_at; }, at_least(0)));
  t.push_back(number({"log_every", outputs, "Iterations between lines of train_log.jsonl", Output},
                     [](auto& c) -> auto& { return c.log_every; }, positive()));
  t.push_back(flag({"quiet", outputs, "No progress line", Output}, [](auto& c) -> auto& { return c.quiet; }));
  return t;
}

}  // namespace

std::string flag_of(std::string_view name) {
  std::string f = "--" + std::string(name);
  std::replace(f.begin(), f.end(), '_', '-');
  return f;
}

std::string TrainOption::flag() const { return flag_of(name); }

const std::vector<TrainOption>& train_options() {
  static const std::vector<TrainOption> table = declare();
  return table;
}

const TrainOption* find_train_option(std::string_view name) {
  for (const TrainOption& o : train_options()) {
    if (o.name == name) return &o;
    for (const auto& alias : o.aliases)
      if (alias == name) return &o;
  }
  return nullptr;
}

json value_when_absent(const TrainOption& o) { return o.absent_means.is_null() ? o.get(TrainConfig{}) : o.absent_means; }

json with_current_names(const json& options) {
  json out = json::object();
  for (const auto& [key, value] : options.items()) {
    const TrainOption* o = find_train_option(key);
    out[o ? o->name : key] = value;
  }
  return out;
}

}  // namespace d2gs
