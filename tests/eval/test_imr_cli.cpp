// `d2gs imr` end to end: PLY files and run folders in, table and JSON out, same numbers as the library.
#include <fstream>
#include <random>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/eval/imr.hpp"
#include "d2gs/model/ply.hpp"
#include "d2gs/scene/scene.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {

Gaussians random_model(std::size_t n, unsigned seed) {
  Gaussians g;
  g.resize(n, 1);
  std::mt19937 rng(seed);
  std::normal_distribution<float> n01;
  for (auto& v : g.means) v = n01(rng);
  for (auto& v : g.log_scales) v = -3.5f + 0.5f * n01(rng);
  for (auto& v : g.quats) v = n01(rng);
  for (auto& v : g.opacity_logits) v = n01(rng);
  return g;
}

TEST(ImrCli, PlyFilesAndRunFoldersAgreeWithTheLibrary) {
  const auto dir = test::scratch_dir();
  const std::vector<Gaussians> models = {random_model(900, 1), random_model(800, 2), random_model(700, 3)};
  write_gaussians_ply(dir / "a.ply", models[0]);
  std::filesystem::create_directories(dir / "run_b/point_cloud/iteration_1000");
  std::filesystem::create_directories(dir / "run_b/point_cloud/iteration_7000");
  write_gaussians_ply(dir / "run_b/point_cloud/iteration_1000/point_cloud.ply", models[2]);  // not the highest
  write_gaussians_ply(dir / "run_b/point_cloud/iteration_7000/point_cloud.ply", models[1]);
  write_gaussians_ply(dir / "c.ply", models[2]);
  const auto fern = test::shared_data() / "nerf_llff_data/fern";
  const auto r = test::run_cli("imr '" + (dir / "a.ply").string() + "' '" + (dir / "run_b").string() + "' '" +
                               (dir / "c.ply").string() + "' -s '" + fern.string() +
                               "' -r 8 --samples 300 --debiased --json '" + (dir / "imr.json").string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("IMR = "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("IMR (debiased) = "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("iteration_7000"), std::string::npos) << r.output;
  std::ifstream in(dir / "imr.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  ASSERT_EQ(j["pairs"].size(), 3u);
  ASSERT_EQ(j["self"].size(), 3u);

  SceneLoadOptions load;
  load.resolution = 8;
  const Camera cam = load_scene(fern, load).cameras[0];
  ImrOptions o;
  o.mixture.samples = 300;
  o.debiased = true;
  std::vector<GaussianMixture> mixtures;
  for (const auto& m : models) mixtures.push_back(mixture_from_model(m, cam, o.mixture));
  const ImrResult expected = compute_imr(mixtures, o);
  EXPECT_DOUBLE_EQ(j["imr"].get<double>(), expected.imr);
  EXPECT_DOUBLE_EQ(j["imr_debiased"].get<double>(), *expected.imr_debiased);
  for (std::size_t k = 0; k < 3; ++k) {
    EXPECT_DOUBLE_EQ(j["pairs"][k]["transport_cost"].get<double>(), expected.pairs[k].transport.transport_cost);
    EXPECT_TRUE(j["pairs"][k]["converged"].get<bool>());
  }
  EXPECT_EQ(j["models"][1]["components"].get<std::size_t>(), mixtures[1].size());

  // ε-scaling is the default; without it the solver reaches the same plan from ε itself.
  EXPECT_TRUE(j["options"]["epsilon_scaling"].get<bool>());
  const auto plain = test::run_cli("imr '" + (dir / "a.ply").string() + "' '" + (dir / "c.ply").string() + "' -s '" +
                                   fern.string() + "' -r 8 --samples 300 --no-epsilon-scaling --json '" +
                                   (dir / "plain.json").string() + "'");
  ASSERT_EQ(plain.exit_code, 0) << plain.output;
  std::ifstream in_plain(dir / "plain.json");
  const nlohmann::json p = nlohmann::json::parse(in_plain);
  EXPECT_FALSE(p["options"]["epsilon_scaling"].get<bool>());
  const double scaled_cost = expected.pairs[1].transport.transport_cost;  // pair (a, c)
  EXPECT_NEAR(p["pairs"][0]["transport_cost"].get<double>(), scaled_cost, 1e-4 * scaled_cost);

  // --strata-phase 1: another subsample by the same rule, recorded, and what the library gives for it.
  const auto phased = test::run_cli("imr '" + (dir / "a.ply").string() + "' '" + (dir / "c.ply").string() + "' -s '" +
                                    fern.string() + "' -r 8 --samples 300 --strata-phase 1 --json '" +
                                    (dir / "phase.json").string() + "'");
  ASSERT_EQ(phased.exit_code, 0) << phased.output;
  std::ifstream in_phase(dir / "phase.json");
  const nlohmann::json ph = nlohmann::json::parse(in_phase);
  EXPECT_EQ(ph["options"]["strata_phase"].get<std::size_t>(), 1u);
  EXPECT_EQ(j["options"]["strata_phase"].get<std::size_t>(), 0u);
  ImrOptions o1 = o;
  o1.debiased = false;
  o1.mixture.phase = 1;
  const ImrResult expected1 =
      compute_imr({mixture_from_model(models[0], cam, o1.mixture), mixture_from_model(models[2], cam, o1.mixture)}, o1);
  EXPECT_DOUBLE_EQ(ph["imr"].get<double>(), expected1.imr);
  EXPECT_NE(ph["pairs"][0]["scale"].get<double>(), j["pairs"][1]["scale"].get<double>())
      << "phase 1 took the release's subsample";
}

TEST(ImrCli, WarnsWithoutSceneAndRejectsBadInput) {
  const auto dir = test::scratch_dir();
  write_gaussians_ply(dir / "a.ply", random_model(200, 4));
  write_gaussians_ply(dir / "b.ply", random_model(200, 5));
  const std::string a = "'" + (dir / "a.ply").string() + "'", b = "'" + (dir / "b.ply").string() + "'";
  const auto ok = test::run_cli("imr " + a + " " + b + " --cost on-the-fly");
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_NE(ok.output.find("identity camera"), std::string::npos) << ok.output;
  EXPECT_EQ(test::run_cli("imr " + a).exit_code, 1);
  EXPECT_EQ(test::run_cli("imr " + a + " " + b + " --cost sparse").exit_code, 1);
  const auto missing = test::run_cli("imr " + a + " '" + (dir / "nothing").string() + "'");
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.output.find("no such model file or run folder"), std::string::npos) << missing.output;
  // --json replaces an earlier result only: not an input model, nor any other file.
  const std::string model_a = read_file(dir / "a.ply");
  const auto onto_input = test::run_cli("imr " + a + " " + b + " --samples 100 --json " + a);
  EXPECT_EQ(onto_input.exit_code, 1) << onto_input.output;
  EXPECT_NE(onto_input.output.find("a.ply: exists and is not an earlier result of d2gs imr"), std::string::npos)
      << onto_input.output;
  EXPECT_EQ(read_file(dir / "a.ply"), model_a);
  const std::string out = "'" + (dir / "imr.json").string() + "'";
  EXPECT_EQ(test::run_cli("imr " + a + " " + b + " --samples 100 --json " + out).exit_code, 0);
  EXPECT_EQ(test::run_cli("imr " + a + " " + b + " --samples 100 --json " + out).exit_code, 0);  // its own: replaced
  const auto threads = test::run_cli("imr " + a + " " + b + " --threads 100000");
  EXPECT_EQ(threads.exit_code, 1) << threads.output;
  EXPECT_NE(threads.output.find("option --threads must be in [0, 1024] (got 100000)"), std::string::npos) << threads.output;
  const auto empty_run = test::run_cli("imr " + a + " '" + dir.string() + "'");
  EXPECT_EQ(empty_run.exit_code, 1);
  EXPECT_NE(empty_run.output.find("point_cloud/iteration_N"), std::string::npos) << empty_run.output;
}

// Run folders record their scene and split: models of two scenes (or two splits of one) are no IMR, and a
// -s naming another scene than the runs' would give them the wrong reference camera.
TEST(ImrCli, RunsOfAnotherSceneOrSplitAreRefused) {
  const auto dir = test::scratch_dir();
  const auto fern = test::shared_data() / "nerf_llff_data/fern";
  const auto horns = test::shared_data() / "llff_nex_reprocessed/horns";
  const auto run = [&](const std::string& name, const std::filesystem::path& source, int views, const char* method) {
    std::filesystem::create_directories(dir / name / "point_cloud/iteration_10");
    write_gaussians_ply(dir / name / "point_cloud/iteration_10/point_cloud.ply", random_model(200, views + name.size()));
    const nlohmann::json j = {{"source", source.string()}, {"resolution", 8}, {"n_views", views}, {"method", method}};
    std::ofstream(dir / name / "config.json") << j.dump();
    return "'" + (dir / name).string() + "'";
  };
  const std::string a = run("a", fern, 3, "d2gs"), b = run("b", fern, 3, "d2gs"), c = run("c", horns, 3, "d2gs"),
                    d = run("d", fern, 6, "d2gs"), e = run("e", fern, 3, "dropgaussian");
  const auto same = test::run_cli("imr " + a + " " + b + " --samples 100");
  EXPECT_EQ(same.exit_code, 0) << same.output;
  EXPECT_EQ(same.output.find("[W]"), std::string::npos) << same.output;
  const auto scenes = test::run_cli("imr " + a + " " + b + " " + c + " --samples 100");
  EXPECT_EQ(scenes.exit_code, 1) << scenes.output;
  EXPECT_NE(scenes.output.find((dir / "c/config.json").string() + ": the run's scene folder is"), std::string::npos)
      << scenes.output;
  const auto split = test::run_cli("imr " + a + " " + d + " --samples 100");
  EXPECT_EQ(split.exit_code, 1) << split.output;
  EXPECT_NE(split.output.find("the run's n_views is 6, that of"), std::string::npos) << split.output;
  const auto flag = test::run_cli("imr " + a + " " + b + " -s '" + horns.string() + "' --samples 100");
  EXPECT_EQ(flag.exit_code, 1) << flag.output;
  EXPECT_NE(flag.output.find("not on the scene -s"), std::string::npos) << flag.output;
  const auto methods = test::run_cli("imr " + a + " " + e + " --samples 100");
  EXPECT_EQ(methods.exit_code, 0) << methods.output;
  EXPECT_NE(methods.output.find("IMR is defined over models of one method"), std::string::npos) << methods.output;

  // Without -s the reference camera comes from the first run's recorded scene, which must be there.
  const std::string gone = run("gone", dir / "no_such_scene", 3, "d2gs"),
                    gone2 = run("gone2", dir / "no_such_scene", 3, "d2gs");
  const auto missing = test::run_cli("imr " + gone + " " + gone2 + " --samples 100");
  EXPECT_EQ(missing.exit_code, 1) << missing.output;
  EXPECT_NE(missing.output.find((dir / "gone/config.json").string() + ": cannot read the run's scene: the recorded "
                                "scene '" + (dir / "no_such_scene").string() + "' is not a folder from here"),
            std::string::npos)
      << missing.output;
  std::ofstream(dir / "b/config.json") << nlohmann::json{{"source", fern.string()}, {"n_views", 3}}.dump();
  const auto no_resolution = test::run_cli("imr " + b + " " + a + " --samples 100");
  EXPECT_EQ(no_resolution.exit_code, 1) << no_resolution.output;
  EXPECT_NE(no_resolution.output.find((dir / "b/config.json").string() + ": cannot read the run's scene: no 'resolution'"),
            std::string::npos)
      << no_resolution.output;
  // With -s the recorded resolution is not needed (the flag's is used).
  const auto with_flag = test::run_cli("imr " + b + " " + a + " -s '" + fern.string() + "' -r 8 --samples 100");
  EXPECT_EQ(with_flag.exit_code, 0) << with_flag.output;
}

// Options are checked before any model is read: the models here do not even exist.
TEST(ImrCli, OptionsAreCheckedBeforeTheModelsAreLoaded) {
  const auto dir = test::scratch_dir();
  const std::string models = "'" + (dir / "a.ply").string() + "' '" + (dir / "b.ply").string() + "'";
  for (const auto& [option, expected] : std::vector<std::pair<std::string, std::string>>{
           {"--epsilon 0", "--epsilon must be positive"},
           {"--epsilon -1", "--epsilon must be positive"},
           {"--tolerance -1", "--tolerance"},
           {"--marginal-tolerance -1e-7", "--marginal-tolerance must be ≥ 0"},
           {"--marginal-tolerance nan", "option --marginal-tolerance: 'nan' is not a finite number"},
           {"--max-iterations 0", "--max-iterations"},
           {"--reference-camera -2", "--reference-camera"},
           {"--threads -1", "--threads"},
           {"--cost sparse", "--cost"},
           {"--anderson -1", "--anderson must be in [0, 100]"},
           {"--epsilon-factor 1", "--epsilon-factor must be in (0, 1)"},
           {"--stage-tolerance 0", "--stage-tolerance must be positive"},
           {"--plain-solver --accelerated", "exclude each other"},
           {"-s somewhere -r 3", "1, 2, 4 or 8"},
           // Read by CLI11 as 0, or clamped to 2^64 - 1: refused as d2gs train refuses them.
           {"--samples ''", "d2gs: error: imr: option --samples: '' is not a whole number ≥ 0\n"},
           {"--samples 99999999999999999999999",
            "option --samples: '99999999999999999999999' is not a whole number ≥ 0"},
           {"--strata-phase 18446744073709551616",
            "option --strata-phase: '18446744073709551616' is not a whole number ≥ 0"},
           {"--max-iterations 10 --max-iterations 20", "d2gs: error: imr: --max-iterations given twice\n"},
           // Below what the float cost resolves: the solve stopped in rounding and said "converged".
           {"--epsilon 1e-300", "option --epsilon must be ≥ 1e-06 on the mean-normalised cost (got 1e-300)"},
           {"--json ''", "option --json: must not be empty"}}) {
    const auto r = test::run_cli("imr " + models + " " + option);
    EXPECT_EQ(r.exit_code, 1) << option << "\n" << r.output;
    EXPECT_NE(r.output.find(expected), std::string::npos) << option << "\n" << r.output;
    EXPECT_EQ(r.output.find("no such model"), std::string::npos) << option << ": models were loaded first\n" << r.output;
  }
  const auto samples = test::run_cli("imr " + models + " --samples -1");
  EXPECT_NE(samples.exit_code, 0) << samples.output;
  EXPECT_NE(samples.output.find("--samples"), std::string::npos) << samples.output;
  const auto phase = test::run_cli("imr " + models + " --strata-phase -1");
  EXPECT_NE(phase.exit_code, 0) << phase.output;
  EXPECT_NE(phase.output.find("--strata-phase"), std::string::npos) << phase.output;
  // --json under a file: refused before any work.
  write_gaussians_ply(dir / "real.ply", random_model(50, 1));
  const auto json = test::run_cli("imr '" + (dir / "real.ply").string() + "' '" + (dir / "real.ply").string() +
                                  "' --json '" + (dir / "real.ply/out.json").string() + "'");
  EXPECT_EQ(json.exit_code, 1) << json.output;
  EXPECT_NE(json.output.find((dir / "real.ply/out.json").string() + ": cannot write here"), std::string::npos)
      << json.output;
  EXPECT_EQ(json.output.find("model 0"), std::string::npos) << json.output;
  // --json in a folder where no file can be created although access() says it can (/proc for root): found by
  // creating a probe file, before any work (it was found when writing, after the solve and the table).
  const auto proc = test::run_cli("imr '" + (dir / "real.ply").string() + "' '" + (dir / "real.ply").string() +
                                  "' --json /proc/d2gs-imr.json");
  EXPECT_EQ(proc.exit_code, 1) << proc.output;
  EXPECT_NE(proc.output.find("/proc/d2gs-imr.json: cannot write here: folder /proc is not writable"), std::string::npos)
      << proc.output;
  EXPECT_EQ(proc.output.find("model 0"), std::string::npos) << proc.output;
  EXPECT_EQ(test::count_occurrences(proc.output, "\n"), 1u) << proc.output;
}

TEST(ImrCli, EmptyModelsAreNamedAndIdenticalModelsSaidSo) {
  const auto dir = test::scratch_dir();
  write_gaussians_ply(dir / "a.ply", random_model(200, 4));
  write_gaussians_ply(dir / "empty.ply", Gaussians{});
  const std::string a = "'" + (dir / "a.ply").string() + "'";
  const auto empty = test::run_cli("imr " + a + " '" + (dir / "empty.ply").string() + "'");
  EXPECT_EQ(empty.exit_code, 1) << empty.output;
  EXPECT_NE(empty.output.find((dir / "empty.ply").string() + ": the model has no Gaussians"), std::string::npos)
      << empty.output;
  // The same model twice: a result, with what it means.
  const auto same = test::run_cli("imr " + a + " " + a + " --samples 0 --json '" + (dir / "same.json").string() + "'");
  ASSERT_EQ(same.exit_code, 0) << same.output;
  EXPECT_NE(same.output.find("(identical models)"), std::string::npos) << same.output;
  EXPECT_NE(same.output.find("note: all models are identical"), std::string::npos) << same.output;
  const auto j = nlohmann::json::parse(std::ifstream(dir / "same.json"));
  EXPECT_TRUE(j["pairs"][0]["identical_models"].get<bool>());
  EXPECT_TRUE(j["converged"].get<bool>());
  // Debiased, identical models are at divergence 0 and the debiased IMR is undefined, which is said.
  const auto debiased = test::run_cli("imr " + a + " " + a + " --samples 0 --debiased");
  ASSERT_EQ(debiased.exit_code, 0) << debiased.output;
  EXPECT_NE(debiased.output.find("IMR (debiased): undefined"), std::string::npos) << debiased.output;
  // One Gaussian twice: every cost is 0, so S = 0 exactly and the IMR (ln 0/0) is undefined: one line,
  // not "cannot normalise".
  write_gaussians_ply(dir / "one.ply", random_model(1, 7));
  const std::string one = "'" + (dir / "one.ply").string() + "'";
  const auto single = test::run_cli("imr " + one + " " + one);
  EXPECT_EQ(single.exit_code, 1) << single.output;
  EXPECT_NE(single.output.find("every pair of models is at distance 0 (identical models)"), std::string::npos)
      << single.output;
  EXPECT_EQ(single.output.find("cannot normalise"), std::string::npos) << single.output;
  // Two different single Gaussians: a distance.
  write_gaussians_ply(dir / "other.ply", random_model(1, 8));
  const auto pair = test::run_cli("imr " + one + " '" + (dir / "other.ply").string() + "'");
  EXPECT_EQ(pair.exit_code, 0) << pair.output;
  EXPECT_EQ(pair.output.find("identical"), std::string::npos) << pair.output;
}

}  // namespace
}  // namespace d2gs
