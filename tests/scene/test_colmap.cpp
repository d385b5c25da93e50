// COLMAP sparse models: the room scene end to end, reprojection of its tracks, binary/text round trip,
// camera models, and damaged files (truncated at many offsets, impossible counts, unknown models).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/scene/colmap.hpp"
#include "d2gs/scene/llff.hpp"
#include "d2gs/scene/scene.hpp"
#include "scene_test_util.hpp"

namespace d2gs {
namespace {

namespace fs = std::filesystem;
using test::expect_error;

fs::path room_sparse() { return test::room_dir() / "sparse" / "0"; }

TEST(Colmap, RoomLoadsWithKnownFacts) {
  const Scene s = load_scene(test::room_dir());
  EXPECT_EQ(s.format, SceneFormat::Colmap);
  EXPECT_EQ(s.images_folder, "images");
  ASSERT_EQ(s.cameras.size(), 41u);
  EXPECT_EQ(s.sfm_points.size(), 6111u);
  EXPECT_EQ(s.sfm_points.colors.size(), 6111u);
  EXPECT_TRUE(s.warnings.empty());
  for (std::size_t i = 0; i < s.cameras.size(); ++i) {
    const Camera& c = s.cameras[i];
    EXPECT_EQ(c.image_name, fmt::format("img{:03d}.JPG", i + 1));  // sorted by name
    EXPECT_EQ(c.image_path, test::room_dir() / "images" / c.image_name);
    EXPECT_EQ(c.width, 996);
    EXPECT_EQ(c.height, 746);
    EXPECT_EQ(c.resample_factor, 1);
    EXPECT_FALSE(c.has_alpha);
    // PINHOLE parameters of the only camera, as stored in cameras.bin.
    EXPECT_NEAR(c.fx, 769.9233027733142, 1e-9);
    EXPECT_NEAR(c.fy, 769.9233027733142, 1e-9);
    EXPECT_NEAR(c.cx, 490.9121333144042, 1e-9);
    EXPECT_NEAR(c.cy, 363.10047982958315, 1e-9);
    const glm::dmat3 should_be_identity = glm::transpose(c.R_world_to_cam) * c.R_world_to_cam;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) EXPECT_NEAR(should_be_identity[a][b], a == b ? 1.0 : 0.0, 1e-12);
    EXPECT_NEAR(glm::determinant(c.R_world_to_cam), 1.0, 1e-12);
  }
}

TEST(Colmap, RoomTracksReprojectOntoTheirObservations) {
  // Every track element (image_id, point2D_idx) of points3D.bin names a 2D observation in images.bin;
  // projecting the 3D point with the loaded camera of that image must land on it (a bundle-adjusted
  // model: reprojection errors of a pixel or two). This checks the quaternion convention, the camera
  // order (image id -> name -> global index) and the intrinsics together.
  const Scene s = load_scene(test::room_dir());
  const auto model = read_colmap_model(room_sparse());
  std::map<std::uint32_t, const ColmapImage*> image_by_id;
  for (const auto& im : model.images) image_by_id[im.id] = &im;
  std::map<std::string, std::size_t> index_by_name;
  for (std::size_t i = 0; i < s.cameras.size(); ++i) index_by_name[s.cameras[i].image_name] = i;

  // Measured on this model with an independent NumPy script: median 0.74 px, max 3.99 px, and each
  // point's stored error is the mean of its track's reprojection errors to within 0.09 px.
  std::size_t observations = 0, in_front = 0;
  std::vector<double> errors;
  double worst_mean_mismatch = 0;
  for (const auto& p : model.points) {
    const glm::dvec3 X(p.xyz[0], p.xyz[1], p.xyz[2]);
    double sum = 0;
    for (const auto& t : p.track) {
      const ColmapImage& im = *image_by_id.at(t.image_id);
      const Camera& c = s.cameras[index_by_name.at(im.name)];
      ASSERT_LT(t.point2D_idx, im.xys.size());
      EXPECT_EQ(im.point3D_ids[t.point2D_idx], static_cast<std::int64_t>(p.id));  // the two files agree
      ++observations;
      if (test::to_camera(c, X).z > 0) ++in_front;
      const glm::dvec2 uv = test::project(c, X);
      const double err = glm::length(uv - glm::dvec2(im.xys[t.point2D_idx][0], im.xys[t.point2D_idx][1]));
      errors.push_back(err);
      sum += err;
    }
    if (!p.track.empty()) worst_mean_mismatch = std::max(worst_mean_mismatch, std::abs(sum / static_cast<double>(p.track.size()) - p.error));
  }
  ASSERT_GT(observations, 6111u * 2);
  EXPECT_EQ(in_front, observations);
  std::sort(errors.begin(), errors.end());
  EXPECT_LT(errors[errors.size() / 2], 1.0);
  EXPECT_LT(errors.back(), 5.0);
  EXPECT_LT(worst_mean_mismatch, 0.2);
}

TEST(Colmap, RoomPointsMostlyInsideAndInFrontOfEveryView) {
  const Scene s = load_scene(test::room_dir());
  for (const Camera& c : s.cameras) {
    std::size_t front = 0, inside = 0;
    for (const auto& p : s.sfm_points.positions) {
      const glm::dvec3 X(p);
      if (test::to_camera(c, X).z <= 0) continue;
      ++front;
      if (test::inside(c, test::project(c, X))) ++inside;
    }
    EXPECT_EQ(front, s.sfm_points.size()) << c.image_name;
    EXPECT_GT(static_cast<double>(inside), 0.5 * static_cast<double>(s.sfm_points.size())) << c.image_name;
  }
}

TEST(Colmap, RoundTripBinaryTextBinaryIsByteExact) {
  const auto dir = test::scratch_dir();
  const auto model = read_colmap_model(room_sparse());
  ASSERT_EQ(model.cameras.size(), 1u);
  ASSERT_EQ(model.images.size(), 41u);
  ASSERT_EQ(model.points.size(), 6111u);
  write_colmap_text(model, dir / "text");
  ASSERT_TRUE(fs::exists(dir / "text" / "images.txt"));
  const auto from_text = read_colmap_model(dir / "text");  // no .bin there: reads the .txt files
  write_colmap_binary(from_text, dir / "bin");
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"})
    EXPECT_TRUE(read_file(dir / "bin" / f) == read_file(room_sparse() / f)) << f << " differs after the round trip";
  // And the text written again from the text model is identical to the first text.
  write_colmap_text(from_text, dir / "text2");
  for (const char* f : {"cameras.txt", "images.txt", "points3D.txt"})
    EXPECT_EQ(read_file(dir / "text2" / f), read_file(dir / "text" / f)) << f;
}

TEST(Colmap, TextModelLoadsLikeTheBinaryOne) {
  const auto dir = test::scratch_dir();
  const auto root = dir / "room_text";
  write_colmap_text(read_colmap_model(room_sparse()), root / "sparse" / "0");
  fs::create_directory_symlink(test::room_dir() / "images", root / "images");
  const Scene text = load_scene(root);
  const Scene bin = load_scene(test::room_dir());
  ASSERT_EQ(text.cameras.size(), bin.cameras.size());
  EXPECT_EQ(text.sfm_points.size(), bin.sfm_points.size());
  for (std::size_t i = 0; i < bin.cameras.size(); ++i) {
    EXPECT_EQ(text.cameras[i].image_name, bin.cameras[i].image_name);
    EXPECT_EQ(text.cameras[i].fx, bin.cameras[i].fx);
    EXPECT_EQ(text.cameras[i].R_world_to_cam, bin.cameras[i].R_world_to_cam);
    EXPECT_EQ(text.cameras[i].t_world_to_cam, bin.cameras[i].t_world_to_cam);
  }
}

TEST(Colmap, TextParserHandlesCommentsBlankObservationsAndReportsLines) {
  const std::string cams = "# comment\n\n1 SIMPLE_PINHOLE 100 80 90 50 40\n2 PINHOLE 10 10 1 2 3 4\r\n";
  const auto c = parse_colmap_cameras_txt(cams, "cameras.txt");
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c[0].model_id, 0);
  EXPECT_EQ(c[0].params, (std::vector<double>{90, 50, 40}));
  EXPECT_EQ(c[1].params, (std::vector<double>{1, 2, 3, 4}));
  const std::string ims = "# header\n1 1 0 0 0 0 0 0 1 a.png\n\n2 1 0 0 0 1 2 3 1 b.png\n10.5 20.5 -1 3 4 7\n";
  const auto im = parse_colmap_images_txt(ims, "images.txt");
  ASSERT_EQ(im.size(), 2u);
  EXPECT_TRUE(im[0].xys.empty());
  EXPECT_EQ(im[1].name, "b.png");
  EXPECT_EQ(im[1].tvec, (std::array<double, 3>{1, 2, 3}));
  ASSERT_EQ(im[1].xys.size(), 2u);
  EXPECT_EQ(im[1].point3D_ids, (std::vector<std::int64_t>{-1, 7}));

  expect_error([] { parse_colmap_cameras_txt("1 PINHOLE 10 10 1 2 3\n", "cameras.txt"); }, {"cameras.txt", "line 1", "missing"});
  expect_error([] { parse_colmap_cameras_txt("#\n1 PINHOLE 10 10 1 2 3 4 5\n", "cameras.txt"); }, {"cameras.txt", "line 2"});
  expect_error([] { parse_colmap_cameras_txt("1 FISHEYE_X 10 10 1\n", "cameras.txt"); }, {"unknown camera model FISHEYE_X"});
  expect_error([] { parse_colmap_images_txt("1 1 0 0 0 0 0 x 1 a.png\n\n", "images.txt"); }, {"images.txt", "line 1", "'x'"});
  expect_error([] { parse_colmap_points3D_txt("1 0 0 0 300 0 0 0.5\n", "points3D.txt"); }, {"points3D.txt", "300"});
  expect_error([] { parse_colmap_points3D_txt("1 0 0 0 1 2 3 0.5 4\n", "points3D.txt"); }, {"points3D.txt", "missing"});
}

TEST(Colmap, QuaternionConvention) {
  // 90 degrees about z: (w, x, y, z) = (cos 45, 0, 0, sin 45) maps x to y.
  const double h = std::sqrt(0.5);
  const auto R = colmap_quaternion_to_matrix({h, 0, 0, h}, "q");
  const glm::dvec3 y = R * glm::dvec3(1, 0, 0);
  EXPECT_NEAR(y.x, 0, 1e-12);
  EXPECT_NEAR(y.y, 1, 1e-12);
  // Not normalised: normalised on use.
  const auto R2 = colmap_quaternion_to_matrix({2 * h, 0, 0, 2 * h}, "q");
  EXPECT_NEAR((R2 * glm::dvec3(1, 0, 0)).y, 1, 1e-12);
  expect_error([] { colmap_quaternion_to_matrix({0, 0, 0, 0}, "images.bin"); }, {"images.bin", "quaternion"});
  expect_error([] { colmap_quaternion_to_matrix({std::nan(""), 0, 0, 1}, "images.bin"); }, {"images.bin"});
}

// ---- a COLMAP scene made from fern: its SIMPLE_RADIAL cameras.bin, images.bin written from the LLFF poses

glm::dvec4 matrix_to_quaternion(const glm::dmat3& m) {  // (w, x, y, z); m[col][row]
  const auto R = [&](int r, int c) { return m[c][r]; };
  const double w = std::sqrt(std::max(0.0, 1 + R(0, 0) + R(1, 1) + R(2, 2))) / 2;
  return {w, (R(2, 1) - R(1, 2)) / (4 * w), (R(0, 2) - R(2, 0)) / (4 * w), (R(1, 0) - R(0, 1)) / (4 * w)};
}

fs::path make_fern_colmap(const fs::path& dir, const std::vector<ColmapCamera>& cameras) {
  const auto root = dir / "fern_colmap";
  const auto poses = parse_llff_poses(read_npy(test::fern_dir() / "poses_bounds.npy"), "poses_bounds.npy");
  ColmapModel m;
  m.cameras = cameras;
  // Listed in reverse name order and with shuffled ids: the loader sorts by name.
  for (int k = static_cast<int>(poses.size()) - 1; k >= 0; --k) {
    ColmapImage im;
    im.id = static_cast<std::uint32_t>(100 + (k * 7) % 20);
    const auto q = matrix_to_quaternion(poses[static_cast<std::size_t>(k)].R_world_to_cam);
    im.qvec = {q.x, q.y, q.z, q.w};  // glm::dvec4 fields x y z w hold w x y z here
    const glm::dvec3 t = -(poses[static_cast<std::size_t>(k)].R_world_to_cam * poses[static_cast<std::size_t>(k)].center);
    im.tvec = {t.x, t.y, t.z};
    im.camera_id = cameras.front().id;
    im.name = fmt::format("image{:03d}.png", k);
    m.images.push_back(im);
  }
  m.points = read_colmap_points3D(test::fern_dir() / "sparse" / "0");
  write_colmap_binary(m, root / "sparse" / "0");
  fs::create_directory_symlink(test::fern_dir() / "images_8", root / "images_8");
  return root;
}

TEST(Colmap, SimpleRadialFernAgreesWithTheLlffLoaderAndWarns) {
  const auto dir = test::scratch_dir();
  const auto fern_cameras = read_colmap_cameras(test::fern_dir() / "sparse" / "0");
  ASSERT_EQ(fern_cameras.size(), 1u);
  ASSERT_EQ(fern_cameras[0].model_id, static_cast<int>(ColmapCameraModel::SimpleRadial));
  ASSERT_EQ(fern_cameras[0].width, 4032u);
  const auto root = make_fern_colmap(dir, fern_cameras);
  SceneLoadOptions o;
  o.resolution = 8;
  const Scene colmap = load_scene(root, o);
  const Scene llff = load_scene(test::fern_dir(), o);
  EXPECT_EQ(colmap.format, SceneFormat::Colmap);
  EXPECT_EQ(colmap.images_folder, "images_8");
  ASSERT_EQ(colmap.warnings.size(), 1u);
  EXPECT_NE(colmap.warnings[0].find("SIMPLE_RADIAL"), std::string::npos);
  EXPECT_NE(colmap.warnings[0].find("cameras.bin"), std::string::npos);
  ASSERT_EQ(colmap.cameras.size(), llff.cameras.size());
  for (std::size_t i = 0; i < llff.cameras.size(); ++i) {
    const Camera &a = colmap.cameras[i], &b = llff.cameras[i];
    EXPECT_EQ(a.image_name, b.image_name);
    EXPECT_EQ(a.width, 504);
    EXPECT_EQ(a.height, 378);
    // Intrinsics scaled by 504/4032 and 378/3024: the COLMAP f is the LLFF f (3260.526 / 8).
    EXPECT_NEAR(a.fx, b.fx, 1e-3);
    EXPECT_NEAR(a.fy, b.fy, 1e-3);
    EXPECT_NEAR(a.cx, b.cx, 1e-9);
    EXPECT_NEAR(a.cy, b.cy, 1e-9);
    for (int c = 0; c < 3; ++c) {
      for (int r = 0; r < 3; ++r) EXPECT_NEAR(a.R_world_to_cam[c][r], b.R_world_to_cam[c][r], 1e-9);
      EXPECT_NEAR(a.t_world_to_cam[c], b.t_world_to_cam[c], 1e-9);
    }
  }
  EXPECT_EQ(colmap.sfm_points.size(), 10091u);
}

TEST(Colmap, SimplePinholeAndUnsupportedModels) {
  const auto dir = test::scratch_dir();
  ColmapCamera cam;
  cam.id = 3;
  cam.model_id = static_cast<int>(ColmapCameraModel::SimplePinhole);
  cam.width = 4032;
  cam.height = 3024;
  cam.params = {3260.5, 2000.0, 1500.0};
  const auto root = make_fern_colmap(dir / "a", {cam});
  SceneLoadOptions o;
  o.resolution = 8;
  const Scene s = load_scene(root, o);
  EXPECT_TRUE(s.warnings.empty());
  EXPECT_NEAR(s.cameras[0].fx, 3260.5 / 8, 1e-9);
  EXPECT_NEAR(s.cameras[0].cx, 250.0, 1e-9);
  EXPECT_NEAR(s.cameras[0].cy, 187.5, 1e-9);

  cam.model_id = static_cast<int>(ColmapCameraModel::OpenCV);
  cam.params = {3260.5, 3260.5, 2000.0, 1500.0, 0.1, 0, 0, 0};
  const auto root2 = make_fern_colmap(dir / "b", {cam});
  expect_error([&] { load_scene(root2, o); }, {"cameras.bin", "OPENCV", "not supported"});
  EXPECT_EQ(std::string(colmap_model_name(99)), "UNKNOWN");
  EXPECT_EQ(colmap_model_id("FULL_OPENCV"), 6);
  EXPECT_EQ(colmap_model_num_params(11), 16);
}

// An image whose aspect ratio differs from its camera's is another image (it was a warning, and the run
// trained with stretched intrinsics); a uniformly resized image keeps its scaled intrinsics.
TEST(Colmap, AspectMismatchBetweenCameraAndImageIsAnError) {
  const auto dir = test::scratch_dir();
  ColmapCamera cam;
  cam.id = 1;
  cam.model_id = static_cast<int>(ColmapCameraModel::Pinhole);
  cam.width = 4032;
  cam.height = 4032;  // the images are 4:3
  cam.params = {3000, 3000, 2016, 2016};
  SceneLoadOptions o;
  o.resolution = 8;
  expect_error([&] { load_scene(make_fern_colmap(dir / "a", {cam}), o); },
               {"image000.png", "504x378", "camera 1", "4032x4032", "aspect ratios differ"});
  cam.height = 3024;
  const Scene s = load_scene(make_fern_colmap(dir / "b", {cam}), o);
  EXPECT_TRUE(s.warnings.empty());
  EXPECT_NEAR(s.cameras[0].fy, 3000.0 * 378 / 3024, 1e-9);
}

TEST(Colmap, ImagesRefersToUnknownCameraOrDuplicateNameOrId) {
  const auto dir = test::scratch_dir();
  const auto root = test::make_room_copy(dir);
  auto model = read_colmap_model(root / "sparse" / "0");
  model.images[5].camera_id = 77;
  write_colmap_binary(model, root / "sparse" / "0");
  expect_error([&] { load_scene(root); }, {"images.bin", "camera 77"});
  model.images[5].camera_id = 1;
  model.images[5].name = model.images[6].name;
  write_colmap_binary(model, root / "sparse" / "0");
  expect_error([&] { load_scene(root); }, {"images.bin", "twice"});
  model = read_colmap_model(test::room_dir() / "sparse" / "0");
  model.images[5].id = model.images[6].id;
  write_colmap_binary(model, root / "sparse" / "0");
  expect_error([&] { load_scene(root); },
               {"images.bin", fmt::format("image id {} appears twice", model.images[6].id), model.images[5].name,
                model.images[6].name});
  model = read_colmap_model(test::room_dir() / "sparse" / "0");
  model.cameras.push_back(model.cameras[0]);
  write_colmap_binary(model, root / "sparse" / "0");
  expect_error([&] { load_scene(root); }, {"cameras.bin", "camera id 1 appears twice"});
}

// ---- damaged binary files

TEST(ColmapBadInput, TruncatedFilesThrowAtEveryOffset) {
  struct File {
    const char* name;
    std::function<void(std::string_view)> parse;
  };
  const File files[] = {
      {"cameras.bin", [](std::string_view b) { parse_colmap_cameras_bin(b, "cameras.bin"); }},
      {"images.bin", [](std::string_view b) { parse_colmap_images_bin(b, "images.bin"); }},
      {"points3D.bin", [](std::string_view b) { parse_colmap_points3D_bin(b, "points3D.bin"); }},
  };
  for (const auto& f : files) {
    const std::string bytes = read_file(room_sparse() / f.name);
    ASSERT_NO_THROW(f.parse(bytes));
    // Every offset of the first 300 bytes (all of cameras.bin), then a stride through the rest.
    for (std::size_t cut = 0; cut < bytes.size(); cut += cut < 300 ? 1 : 997) {
      SCOPED_TRACE(fmt::format("{} cut at {}", f.name, cut));
      expect_error([&] { f.parse(std::string_view(bytes).substr(0, cut)); }, {f.name});
    }
    // Trailing garbage is corruption too.
    expect_error([&] { f.parse(bytes + "x"); }, {f.name, "unexpected bytes"});
  }
}

TEST(ColmapBadInput, ImpossibleCountsAreRejectedBeforeAllocating) {
  const auto with_count = [](std::string bytes, std::uint64_t n, std::size_t at = 0) {
    std::memcpy(bytes.data() + at, &n, 8);
    return bytes;
  };
  const std::string cams = read_file(room_sparse() / "cameras.bin");
  const std::string ims = read_file(room_sparse() / "images.bin");
  const std::string pts = read_file(room_sparse() / "points3D.bin");
  for (std::uint64_t n : {std::uint64_t{2}, std::uint64_t{1} << 40, ~std::uint64_t{0}}) {
    expect_error([&] { parse_colmap_cameras_bin(with_count(cams, n), "cameras.bin"); }, {"cameras.bin"});
    expect_error([&] { parse_colmap_images_bin(with_count(ims, n + 41), "images.bin"); }, {"images.bin"});
    expect_error([&] { parse_colmap_points3D_bin(with_count(pts, n + 6111), "points3D.bin"); }, {"points3D.bin"});
  }
  // The points2D count of the first image: after the count (8), id (4), pose (56), camera id (4), name.
  const std::size_t at = 8 + 4 + 56 + 4 + std::string("img001.JPG").size() + 1;
  expect_error([&] { parse_colmap_images_bin(with_count(ims, std::uint64_t{1} << 60, at), "images.bin"); },
               {"images.bin", "points2D count"});
  // The track length of the first point: count (8), id (8), xyz (24), rgb (3), error (8).
  expect_error([&] { parse_colmap_points3D_bin(with_count(pts, ~std::uint64_t{0}, 8 + 8 + 24 + 3 + 8), "points3D.bin"); },
               {"points3D.bin", "track length"});
  // An image name without its terminating NUL: one image whose name runs to the end of the file.
  std::string no_nul = with_count(ims.substr(0, 8 + 4 + 56 + 4), 1) + std::string(200, 'a');
  expect_error([&] { parse_colmap_images_bin(no_nul, "images.bin"); }, {"images.bin", "NUL"});
}

TEST(ColmapBadInput, UnknownModelIdNamesTheFile) {
  std::string cams = read_file(room_sparse() / "cameras.bin");
  const std::int32_t bad = 99;
  std::memcpy(cams.data() + 12, &bad, 4);  // after the count (8) and the camera id (4)
  expect_error([&] { parse_colmap_cameras_bin(cams, "x/cameras.bin"); }, {"x/cameras.bin", "unknown camera model id 99"});
  // Through the loader and a real file.
  const auto dir = test::scratch_dir();
  const auto root = test::make_room_copy(dir);
  test::write_bytes(root / "sparse" / "0" / "cameras.bin", cams);
  expect_error([&] { load_scene(root); }, {(root / "sparse" / "0" / "cameras.bin").string(), "unknown camera model id 99"});
}

TEST(ColmapBadInput, TruncatedFilesThroughTheLoader) {
  const auto dir = test::scratch_dir();
  const auto root = test::make_room_copy(dir);
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"}) {
    const auto path = root / "sparse" / "0" / f;
    const std::string good = read_file(path);
    for (std::size_t cut : {std::size_t{0}, std::size_t{5}, std::size_t{40}, good.size() / 2, good.size() - 1}) {
      test::write_bytes(path, good.substr(0, cut));
      expect_error([&] { load_scene(root); }, {path.string()});
    }
    test::write_bytes(path, good);
  }
  EXPECT_NO_THROW(load_scene(root));
}

TEST(ColmapBadInput, MissingImageNamedAtLoad) {
  const auto dir = test::scratch_dir();
  const auto root = test::make_room_copy(dir);
  auto model = read_colmap_model(root / "sparse" / "0");
  model.images[3].name = "img_missing.JPG";
  write_colmap_binary(model, root / "sparse" / "0");
  expect_error([&] { load_scene(root); }, {"img_missing.JPG", "not found", "images.bin"});
}

// Binary bytes in a text model: the message quotes them escaped (a NUL used to end it, raw bytes reached the
// terminal) and still says what is wrong.
TEST(ColmapBadInput, BinaryBytesInTextFilesAreQuotedEscaped) {
  using namespace std::string_literals;
  const auto dir = test::scratch_dir();
  const auto root = dir / "room_text";
  const auto sparse = root / "sparse" / "0";
  write_colmap_text(read_colmap_model(room_sparse()), sparse);
  fs::create_directory_symlink(test::room_dir() / "images", root / "images");
  const std::string cameras = read_file(sparse / "cameras.txt");
  test::write_bytes(sparse / "cameras.txt", "\0\0\0\xff\xfe"s);
  try {
    load_scene(root);
    ADD_FAILURE() << "binary cameras.txt accepted";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_EQ(std::strlen(e.what()), msg.size()) << "the message holds a NUL";
    EXPECT_NE(msg.find((sparse / "cameras.txt").string() + ": line 1: camera id '\\x00\\x00\\x00\\xff\\xfe' is not a valid number"),
              std::string::npos) << msg;
  }
  test::write_bytes(sparse / "cameras.txt", cameras);
  std::string images = read_file(sparse / "images.txt");
  std::size_t line2 = images.find('\n') + 1;
  images.insert(line2, "\xff\xfe");
  test::write_bytes(sparse / "images.txt", images);
  expect_error([&] { load_scene(root); }, {(sparse / "images.txt").string(), "line 2", "'\\xff\\xfe"});
  // Each quoting site: a number, the rest of a line, a camera model name.
  expect_error([] { parse_colmap_images_txt("1 1 0 0 0 0 0 0 1 a.png\n\xff\xfe 1 2\n", "images.txt"); },
               {"images.txt", "line 2: point2D x '\\xff\\xfe' is not a valid number"});
  expect_error([] { parse_colmap_cameras_txt("1 PINHOLE 10 10 1 2 3 4 \x01\x02\n", "cameras.txt"); },
               {"line 1: unexpected text '\\x01\\x02'"});
  expect_error([] { parse_colmap_cameras_txt("1 PIN\x1b[2JHOLE 10 10 1 2 3 4\n", "cameras.txt"); },
               {"unknown camera model PIN\\x1b[2JHOLE"});
  expect_error([] { parse_colmap_cameras_txt("1 PINHOLE 10 10 1 2 3 " + std::string(500, '7') + "x\n", "cameras.txt"); },
               {"camera parameter '" + std::string(60, '7') + "...' is not a valid number"});
}

TEST(ColmapBadInput, NonFiniteValues) {
  const auto dir = test::scratch_dir();
  const auto root = test::make_room_copy(dir);
  auto model = read_colmap_model(root / "sparse" / "0");
  model.images[2].tvec[1] = std::nan("");
  write_colmap_binary(model, root / "sparse" / "0");
  expect_error([&] { load_scene(root); }, {"images.bin", "img003.JPG", "non-finite"});
  model = read_colmap_model(test::room_dir() / "sparse" / "0");
  model.points[10].xyz[0] = INFINITY;
  write_colmap_binary(model, root / "sparse" / "0");
  expect_error([&] { load_scene(root); }, {"points3D.bin", "non-finite"});
  model = read_colmap_model(test::room_dir() / "sparse" / "0");
  model.cameras[0].params[0] = -5;
  write_colmap_binary(model, root / "sparse" / "0");
  expect_error([&] { load_scene(root); }, {"cameras.bin", "focal"});
  // Finite but impossible (each trained to a "successful" 6–12 dB before): a focal of 1e-30 or 1e30, a
  // principal point far outside the image, a camera at 1e300, a point beyond float's range.
  for (const double focal : {1e-30, 1e30}) {
    model = read_colmap_model(test::room_dir() / "sparse" / "0");
    model.cameras[0].params[0] = focal;
    write_colmap_binary(model, root / "sparse" / "0");
    expect_error([&] { load_scene(root); }, {"images.bin", "camera 1 of cameras.bin", "no pinhole camera's"});
  }
  model = read_colmap_model(test::room_dir() / "sparse" / "0");
  model.cameras[0].params[2] = 1e9;  // PINHOLE: fx fy cx cy
  write_colmap_binary(model, root / "sparse" / "0");
  expect_error([&] { load_scene(root); }, {"images.bin", "principal point", "far outside"});
  model = read_colmap_model(test::room_dir() / "sparse" / "0");
  model.images[4].tvec[0] = 1e300;
  write_colmap_binary(model, root / "sparse" / "0");
  expect_error([&] { load_scene(root); }, {"images.bin", model.images[4].name, "beyond 10⁹ units"});
  model = read_colmap_model(test::room_dir() / "sparse" / "0");
  model.points[10].xyz[0] = 1e300;
  write_colmap_binary(model, root / "sparse" / "0");
  expect_error([&] { load_scene(root); }, {"points3D.bin", "beyond any scene"});
  model = read_colmap_model(test::room_dir() / "sparse" / "0");
  model.images[3].qvec = {0, 0, 0, 0};
  write_colmap_binary(model, root / "sparse" / "0");
  expect_error([&] { load_scene(root); }, {"images.bin", "image " + model.images[3].name + ": invalid rotation quaternion"});
}

}  // namespace
}  // namespace d2gs
