#pragma once
// Every option of `d2gs train`, declared once (options.cpp): its name, which is the key of config.json
// and, with '-' for '_', the command-line flag; the former names still accepted; a short flag; the help
// line; its range or choices; and the TrainConfig field that holds it, whose initial value is the
// default. From that one table come to_json and update_from_json (config.json, --config, experiment
// files), the per-option checks of TrainConfig::validate, the run identity a checkpoint is compared
// with, and the command line and --help of `d2gs train` (src/cli/train.cpp).
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

namespace d2gs {

struct TrainConfig;

// How an option takes part in the identity of a run, which a checkpoint must match (checkpoint.hpp).
enum class OptionRole {
  Training,  // changes the training: compared (a path made absolute, keywords as they are)
  Scene,     // resolved into the identity's scene, resolution and split, compared there
  Length,    // --iterations: compared on its own (a resume may train further)
  Output,    // what is written, and when: not compared
};

enum class OptionKind {
  Flag,         // true / false; the command line has --NAME and --no-NAME
  Integer,      // a JSON integer that fits the field
  Real,         // a finite JSON number within the field's type
  Text,         // a string
  Path,         // a string naming a file or folder, or one of `keywords`
  Choice,       // one of `choices`
  IntegerList,  // a JSON list of integers; comma-separated on the command line ("none": empty)
  NameList,     // a JSON list of distinct names from `choices`; comma-separated on the command line
};

struct TrainOption {
  std::string name;                  // the JSON key; the flag is flag()
  std::vector<std::string> aliases;  // former names, accepted as keys and as flags
  std::string short_flag;            // e.g. "-s"; empty for none
  std::string group;                 // heading in --help
  std::string help;
  OptionKind kind = OptionKind::Text;
  OptionRole role = OptionRole::Training;
  std::string type_name;               // shown in --help: INT, FLOAT, PATH, a|b, ...
  std::string range;                   // e.g. "> 0", "[0, 1)", "1, 2, 4 or 8"; empty: any value
  std::vector<std::string> choices;    // Choice: the names (an empty name: none chosen); NameList: the names
  std::vector<std::string> keywords;   // Path: the words that are not paths

  // The field as JSON (the value config.json records).
  std::function<nlohmann::json(const TrainConfig&)> get;
  // Takes a JSON value into the field, checked (core/json_value.hpp): throws d2gs::Error "key 'NAME' ...".
  std::function<void(TrainConfig&, const nlohmann::json&)> set;
  // The field's range: throws d2gs::Error "option --FLAG must be ... (got VALUE)".
  std::function<void(const TrainConfig&)> check;
  // Command-line words as the JSON value set() takes (one word; a Flag gets "true" or "false"; an
  // IntegerList or NameList the list's words); throws d2gs::Error "option --FLAG: ..." for a word of the wrong form.
  std::function<nlohmann::json(const std::vector<std::string>&)> parse;
  // The default as --help shows it.
  std::function<std::string()> default_text;
  // Where the default has changed since the option was added: the value a config.json or a checkpoint
  // without this key was trained with (null: the default, which is how every option is added).
  nlohmann::json absent_means;

  std::string flag() const;  // "--" + name with '-' for '_'
};

// "--" + name with '-' for '_'.
std::string flag_of(std::string_view name);

// The table, in the order --help lists it.
const std::vector<TrainOption>& train_options();
// The option of that name or former name (a JSON key or a flag without its dashes); null for none.
const TrainOption* find_train_option(std::string_view name);
// `options` (config.json keys) with every former name replaced by the option's name; an entry of a
// name that is no option is kept as it is.
nlohmann::json with_current_names(const nlohmann::json& options);
// The value a run recorded without the option's key was trained with: absent_means, else the default.
nlohmann::json value_when_absent(const TrainOption& o);

}  // namespace d2gs
