// The checkpoint format (train/checkpoint.hpp) on synthetic states: an exact round trip, damage and
// truncation anywhere refused with one line, the format numbers, and check_resume's rules.
#include <gtest/gtest.h>

#include <cstring>
#include <functional>

#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/checksum.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/random.hpp"
#include "d2gs/train/checkpoint.hpp"
#include "test_errors.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {
namespace fs = std::filesystem;

RunIdentity identity() {
  RunIdentity r;
  r.scene = "/data/fern";
  r.scene_format = "llff";
  r.images_folder = "images_8";
  r.resolution = 8;
  r.scene_images = 20;
  r.train_views = {1, 10, 19};
  r.test_views = {0, 8, 16};
  r.train_images = {"image001.png", "image010.png", "image019.png"};
  r.train_sizes = {{{8, 6}}, {{8, 6}}, {{8, 6}}};
  r.options = {{"method", "d2gs"}, {"seed", 3}, {"sh_degree", 1}, {"lambda_dssim", 0.2}, {"init", "dense"}};
  return r;
}

Gaussians random_model(Rng& rng, std::size_t n, int degree) {
  Gaussians g;
  g.resize(n, degree);
  for (auto* a : {&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.sh_dc, &g.sh_rest})
    for (float& v : *a) v = static_cast<float>(rng.normal());
  return g;
}

TrainingState state() {
  Rng rng(11);
  TrainingState s;
  s.iteration = 40;
  s.iterations = 100;
  s.active_sh = 1;
  s.adam_step = 39;
  s.elapsed_s = 12.5;
  s.camera_stack = {2, 0};
  s.rng_cameras = Rng::stream(3, "cameras").state();
  Rng dropout = Rng::stream(3, "dropout");
  (void)dropout.normal();  // leaves a spare normal in the state
  s.rng_dropout = dropout.state();
  s.rng_densify = Rng::stream(3, "densify").state();
  s.model = random_model(rng, 17, 1);
  s.exp_avg = random_model(rng, 17, 1);
  s.exp_avg_sq = random_model(rng, 17, 1);
  s.grad_sums.assign(17, 0.25f);
  s.grad_counts.assign(17, 3.0f);
  // A method's state: D²GS's density cache (out of step with the model, as the release's cache may be)
  // and its DAFE masks, and an empty group.
  s.method.floats["density_cache"] = {std::vector<float>(15, 0.5f)};
  s.method.floats["empty"] = {};
  s.method.bytes["dafe_masks"] = {std::vector<std::uint8_t>(48, 1), {}, std::vector<std::uint8_t>(48, 0)};
  return s;
}

TEST(Checkpoint, RoundTripIsExact) {
  const RunIdentity r = identity();
  const TrainingState s = state();
  const std::string bytes = encode_checkpoint(r, s);
  EXPECT_EQ(bytes.substr(0, 10), "D2GSCKPT3\n");
  const Checkpoint c = decode_checkpoint(bytes, "x.bin");
  EXPECT_EQ(c.run.scene, r.scene);
  EXPECT_EQ(c.run.images_folder, r.images_folder);
  EXPECT_EQ(c.run.train_views, r.train_views);
  EXPECT_EQ(c.run.test_views, r.test_views);
  EXPECT_EQ(c.run.train_images, r.train_images);
  EXPECT_EQ(c.run.train_sizes, r.train_sizes);
  EXPECT_EQ(c.run.options, r.options);
  const TrainingState& t = c.state;
  EXPECT_EQ(t.iteration, 40);
  EXPECT_EQ(t.iterations, 100);
  EXPECT_EQ(t.active_sh, 1);
  EXPECT_EQ(t.adam_step, 39);
  EXPECT_EQ(t.elapsed_s, 12.5);
  EXPECT_EQ(t.camera_stack, s.camera_stack);
  EXPECT_EQ(std::memcmp(&t.rng_dropout.spare, &s.rng_dropout.spare, sizeof(double)), 0);
  EXPECT_TRUE(t.rng_dropout.has_spare);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(t.rng_cameras.words[i], s.rng_cameras.words[i]);
  for (const auto& [a, b] : {std::pair{&t.model, &s.model}, {&t.exp_avg, &s.exp_avg}, {&t.exp_avg_sq, &s.exp_avg_sq}}) {
    EXPECT_EQ(a->sh_degree, b->sh_degree);
    EXPECT_EQ(a->means, b->means);
    EXPECT_EQ(a->quats, b->quats);
    EXPECT_EQ(a->sh_rest, b->sh_rest);
  }
  EXPECT_EQ(t.grad_sums, s.grad_sums);
  EXPECT_EQ(t.grad_counts, s.grad_counts);
  EXPECT_EQ(t.method, s.method);
  EXPECT_EQ(t.method.floats.at("empty").size(), 0u);
  EXPECT_EQ(encode_checkpoint(c.run, c.state), bytes);  // and back to the same bytes

  // Through a file, written atomically.
  const auto dir = test::scratch_dir();
  write_checkpoint(dir / "chkpnt40.bin", r, s);
  EXPECT_EQ(read_file(dir / "chkpnt40.bin"), bytes);
  EXPECT_EQ(read_checkpoint(dir / "chkpnt40.bin").state.model.means, s.model.means);
  write_checkpoint(dir / "chkpnt100.bin", r, s);
  write_file_atomic(dir / "chkpnt7.bin", "x");
  write_file_atomic(dir / "chkpnt.bin", "x");
  write_file_atomic(dir / "chkpnt5.bin.old", "x");
  const auto listed = checkpoints_in(dir);
  ASSERT_EQ(listed.size(), 3u);
  EXPECT_EQ(listed[0].first, 100);
  EXPECT_EQ(listed[1].first, 40);
  EXPECT_EQ(listed[2], std::make_pair(7, dir / "chkpnt7.bin"));
}

TEST(Checkpoint, DamageAnywhereIsRefusedWithOneLine) {
  const std::string bytes = encode_checkpoint(identity(), state());
  // Every byte changed in turn: the header, the arrays and the checksum itself.
  for (std::size_t i = 0; i < bytes.size(); ++i) {
    std::string damaged = bytes;
    damaged[i] = static_cast<char>(damaged[i] ^ 0x10);
    const std::string message = test::error_of([&] { (void)decode_checkpoint(damaged, "c.bin"); });
    ASSERT_EQ(message.rfind("c.bin: ", 0), 0u) << "byte " << i << " changed was not found: '" << message << "'";
    ASSERT_EQ(message.find('\n'), std::string::npos) << message;
  }
  // Every truncation.
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    const std::string message = test::error_of([&] { (void)decode_checkpoint(std::string_view(bytes).substr(0, n), "c.bin"); });
    ASSERT_EQ(message.rfind("c.bin: ", 0), 0u) << "truncated to " << n << ": '" << message << "'";
  }
  EXPECT_EQ(test::error_of([&] { (void)decode_checkpoint(bytes.substr(0, bytes.size() - 10), "c.bin"); }),
            fmt::format("c.bin: truncated checkpoint ({} bytes of {})", bytes.size() - 10, bytes.size()));
  EXPECT_EQ(test::error_of([&] { (void)decode_checkpoint(bytes + "xyz", "c.bin"); }), "c.bin: damaged checkpoint: 3 bytes after its end");
  std::string flipped = bytes;
  flipped[bytes.size() - 100] ^= 0x01;
  EXPECT_EQ(test::error_of([&] { (void)decode_checkpoint(flipped, "c.bin"); }).rfind("c.bin: damaged checkpoint: CRC-32 mismatch", 0), 0u);
}

TEST(Checkpoint, FormatNumbers) {
  std::string bytes = encode_checkpoint(identity(), state());
  EXPECT_EQ(test::error_of([&] { (void)decode_checkpoint("D2GSCKPT1\n" + bytes.substr(10), "c.bin"); }),
            "c.bin: checkpoint format 1 (written by d2gs before 2026-11-25) records neither the scene nor the split it was "
            "trained on, so a resume from it cannot be checked; train the run again");
  EXPECT_EQ(test::error_of([&] { (void)decode_checkpoint("D2GSCKPT4\n" + bytes.substr(10), "c.bin"); }),
            "c.bin: checkpoint format 4 is not one this d2gs reads (formats 2 and 3)");
  for (const char* other : {"", "D2GS", "D2GSCKPT", "D2GSCKPT\n", "D2GSCKPTx\n", "D2GSCKPT12345678\n", "ply\nformat"})
    EXPECT_EQ(test::error_of([&] { (void)decode_checkpoint(other, "c.bin"); }), "c.bin: not a d2gs checkpoint") << other;
}

TEST(Checkpoint, ResumeRules) {
  const RunIdentity r = identity();
  Checkpoint c{r, state()};
  EXPECT_EQ(check_resume("c.bin", c, r, 100), "");
  const auto refused = [&](RunIdentity other, int iterations = 100) {
    return test::error_of([&] { (void)check_resume("c.bin", c, other, iterations); });
  };
  auto other = r;
  other.images_folder = "images";
  EXPECT_EQ(refused(other), "c.bin: cannot resume: it was trained on the images of images_8/, this run reads images/");
  other = r;
  other.scene_images = 21;
  EXPECT_EQ(refused(other), "c.bin: cannot resume: the scene had 20 images when it was written, it has 21 now");
  other = r;
  other.train_images[1] = "image011.png";
  EXPECT_EQ(refused(other), "c.bin: cannot resume: training view 10 was image010.png, it is image011.png now");
  other = r;
  other.train_sizes[2] = {{6, 8}};
  EXPECT_EQ(refused(other), "c.bin: cannot resume: training view 19 (image019.png) was 8×6, it is 6×8 now");
  other = r;
  other.options.erase("init");
  EXPECT_EQ(refused(other), "c.bin: cannot resume: it was trained with init = \"dense\", this run has (no such option)");
  // An option newer than the checkpoint (its identity lacks it): accepted at its default, which is what the
  // code did before the option existed, and refused at any other value.
  Checkpoint older{r, state()};
  ASSERT_FALSE(older.run.options.contains("stereo_depth_lambda"));
  other = r;
  other.options["stereo_depth_lambda"] = 0.05;  // the default
  EXPECT_EQ(check_resume("c.bin", older, other, 100), "");
  other = r;
  other.options["stereo_depth_lambda"] = 0.5;
  EXPECT_EQ(test::error_of([&] { (void)check_resume("c.bin", older, other, 100); }),
            "c.bin: cannot resume: it was trained with stereo_depth_lambda = (no such option), this run has 0.5");
  // An option whose default changed after it was added: a checkpoint without it was trained at the former
  // default (image_source: images_R/ until issue 23 made PIL's resize of the largest folder the default).
  ASSERT_FALSE(older.run.options.contains("image_source"));
  EXPECT_EQ(TrainConfig{}.image_source, ImageSource::Largest);
  other = r;
  other.options["image_source"] = "largest";  // today's default
  EXPECT_EQ(test::error_of([&] { (void)check_resume("c.bin", older, other, 100); }),
            "c.bin: cannot resume: it was trained with image_source = (no such option), this run has \"largest\"");
  other.options["image_source"] = "folder";
  EXPECT_EQ(check_resume("c.bin", older, other, 100), "");

  // --iterations.
  EXPECT_EQ(refused(r, 39), "c.bin: cannot resume: it is at iteration 40, beyond --iterations 39; resume with "
                            "--iterations 40 or more");
  EXPECT_NE(refused(r, 40).find("it is iteration 40 of a 100-iteration run"), std::string::npos);
  EXPECT_EQ(check_resume("c.bin", c, r, 41),
            "c.bin: resuming a 100-iteration run to 41 iterations: the learning-rate and drop-rate schedules change "
            "from iteration 41 on, so the model is not that of an uninterrupted 41-iteration run");
  c.state.iterations = 40;  // the checkpoint of a run's last iteration
  EXPECT_EQ(check_resume("c.bin", c, r, 40), "");
  c.state.iterations = 100;

  // A state that does not fit the run, even under an equal identity (the memory-safety checks).
  c.state.camera_stack = {1, 3};
  EXPECT_EQ(refused(r), "c.bin: cannot resume: its camera queue names training view position 3 of 3");
  c.state.camera_stack = {1, 1};
  EXPECT_EQ(refused(r), "c.bin: cannot resume: its camera queue names training view position 1 of 3");
  c.state.camera_stack = {};
  EXPECT_EQ(check_resume("c.bin", c, r, 100), "");
}

// A state no run can be in is refused naming the field (it said "impossible state (iteration 10, ...)" alone).
TEST(Checkpoint, AnImpossibleStateNamesItsField) {
  const RunIdentity r = identity();
  for (const auto& [change, expected] : std::vector<std::pair<std::function<void(TrainingState&)>, std::string>>{
           {[](TrainingState& s) { s.adam_step = -1; }, "adam_step -1 is negative"},
           {[](TrainingState& s) { s.iteration = -3; }, "iteration -3 is negative"},
           {[](TrainingState& s) { s.iterations = 0; }, "--iterations 0 is below 1"},
           {[](TrainingState& s) { s.active_sh = 2; }, "active SH degree 2 is outside 0..1"}}) {
    TrainingState s = state();
    change(s);
    const std::string message = test::error_of([&] { (void)decode_checkpoint(encode_checkpoint(r, s), "c.bin"); });
    EXPECT_EQ(message.rfind("c.bin: damaged checkpoint: impossible state: " + expected + " (", 0), 0u) << message;
  }
}

// A format-2 checkpoint (d2gs before the methods seam): D²GS's density cache and DAFE masks sat at fixed
// places after the densification statistics; they are read into the method's state groups, and a
// checkpoint of another method (both empty) has none.
std::string format2_bytes(const RunIdentity& r, TrainingState s, const std::vector<float>& density,
                          const std::vector<std::vector<std::uint8_t>>& masks) {
  s.method = {};
  const std::string v3 = encode_checkpoint(r, s);
  std::uint64_t header_bytes = 0;
  std::memcpy(&header_bytes, v3.data() + 10, 8);
  nlohmann::json header = nlohmann::json::parse(v3.substr(18, header_bytes));
  std::string body = v3.substr(18 + header_bytes, v3.size() - 18 - header_bytes - 4);
  const auto put = [&body](const void* data, std::uint64_t count, std::size_t size) {
    body.append(reinterpret_cast<const char*>(&count), 8);
    body.append(static_cast<const char*>(data), count * size);
  };
  put(density.data(), density.size(), sizeof(float));
  for (const auto& m : masks) put(m.data(), m.size(), 1);
  header["format"] = 2;
  header["body_bytes"] = body.size();
  header["state"].erase("method_state");
  header["state"]["dafe_masks"] = masks.size();
  const std::string text = header.dump();
  std::string out = "D2GSCKPT2\n";
  const std::uint64_t n = text.size();
  out.append(reinterpret_cast<const char*>(&n), 8);
  out += text + body;
  const std::uint32_t crc = crc32(out);
  out.append(reinterpret_cast<const char*>(&crc), 4);
  return out;
}

TEST(Checkpoint, Format2StillLoads) {
  const RunIdentity r = identity();
  const TrainingState s = state();
  const std::vector<float> density(15, 0.5f);
  const std::vector<std::vector<std::uint8_t>> masks = {std::vector<std::uint8_t>(48, 1), {}, {}};
  const Checkpoint d2gs = decode_checkpoint(format2_bytes(r, s, density, masks), "old.bin");
  EXPECT_EQ(d2gs.state.model.means, s.model.means);
  EXPECT_EQ(d2gs.state.grad_counts, s.grad_counts);
  EXPECT_EQ(d2gs.state.method.floats.at("density_cache"), std::vector<std::vector<float>>{density});
  EXPECT_EQ(d2gs.state.method.bytes.at("dafe_masks"), masks);
  // 3DGS: an empty cache and a mask slot per view, all empty: no state.
  const Checkpoint gs3d = decode_checkpoint(format2_bytes(r, s, {}, {{}, {}, {}}), "old.bin");
  EXPECT_TRUE(gs3d.state.method.floats.empty());
  EXPECT_TRUE(gs3d.state.method.bytes.empty());
  // Re-encoded, it is format 3.
  EXPECT_EQ(encode_checkpoint(d2gs.run, d2gs.state).substr(0, 10), "D2GSCKPT3\n");
}

}  // namespace
}  // namespace d2gs
