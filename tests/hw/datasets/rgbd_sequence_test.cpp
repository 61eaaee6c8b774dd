// Tests for the RGB-D sequence readers (hw/datasets/src/rgbd_sequence.cpp): both layouts on the
// shared data and on malformed, truncated, NaN and empty files. Long because the reader is.
#include <tessera/datasets/rgbd_sequence.hpp>

#include <zlib.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <random>
#include <sstream>

#include "../../shared_data.hpp"
#include "mutate.hpp"

namespace fs = std::filesystem;
using namespace tessera::datasets;
using namespace tessera::io;

namespace {

constexpr const char* kTum = "tum-rgbd-fr1-desk-9frames";
constexpr const char* kSeven = "7scenes-redkitchen-rgbd";

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), {});
}

void spit(const fs::path& p, const std::string& s) {
  std::ofstream(p, std::ios::binary) << s;
}

std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const DatasetError& e) {
    return e.what();
  }
  return "";
}

template <typename Parse>
std::string parseError(const std::string& name, const std::string& text, Parse parse) {
  return errorOf([&] {
    TextReader r = TextReader::fromString(name, text);
    (void)parse(r);
  });
}

double median(std::vector<float> v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](float x) { return !std::isfinite(x); }), v.end());
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

void checkRotation(const Eigen::Isometry3d& T) {
  const Eigen::Matrix3d R = T.rotation();
  CHECK((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-9);
  CHECK(R.determinant() == Approx(1.0).margin(1e-9));
  CHECK(T.translation().allFinite());
}

// Checks a decoded frame: sizes, depth statistics in a Kinect's range, colour not constant.
void checkImages(const RgbdImages& im, double& median_m, double& valid_fraction) {
  REQUIRE(im.width == 640);
  REQUIRE(im.height == 480);
  REQUIRE(im.color.size() == 640u * 480u * 3u);
  REQUIRE(im.depth.size() == 640u * 480u);
  const auto metres = depthInMetres(im);
  median_m = median(metres);
  valid_fraction = static_cast<double>(std::count_if(im.depth.begin(), im.depth.end(),
                                                     [](std::uint16_t d) { return d != 0; })) /
                   static_cast<double>(im.depth.size());
  const auto [lo, hi] = std::minmax_element(im.color.begin(), im.color.end());
  CHECK(*hi - *lo > 100);
  const auto implausible = std::count_if(metres.begin(), metres.end(), [](float m) {
    return std::isfinite(m) && !(m > 0.1f && m < 10.0f);  // beyond a Kinect's range
  });
  CHECK(implausible == 0);
}

// A scratch copy of the TUM folder whose text files can be edited; images are symlinked.
fs::path tumCopy(const fs::path& src, const std::string& name) {
  const fs::path dir = tessera::test::scratchDir(name) / "rgbd_dataset_freiburg1_desk";
  fs::create_directories(dir);
  for (const char* f : {"rgb.txt", "depth.txt", "groundtruth.txt", "associations.txt"})
    fs::copy_file(src / f, dir / f);
  fs::create_directories(dir / "rgb");
  fs::create_directories(dir / "depth");
  for (const char* sub : {"rgb", "depth"})
    for (const auto& e : fs::directory_iterator(src / sub))
      fs::create_symlink(fs::absolute(e.path()), dir / sub / e.path().filename());
  return dir;
}

// A scratch 7-Scenes folder with frames [0, n) symlinked and the text files copied.
fs::path sevenCopy(const fs::path& src, const std::string& name, int n) {
  const fs::path dir = tessera::test::scratchDir(name);
  fs::copy_file(src / "camera-intrinsics.txt", dir / "camera-intrinsics.txt");
  for (int i = 0; i < n; ++i) {
    char stem[32];
    std::snprintf(stem, sizeof stem, "frame-%06d", i);
    const std::string s = stem;
    fs::create_symlink(fs::absolute(src / (s + ".color.jpg")), dir / (s + ".color.jpg"));
    fs::create_symlink(fs::absolute(src / (s + ".depth.png")), dir / (s + ".depth.png"));
    fs::copy_file(src / (s + ".pose.txt"), dir / (s + ".pose.txt"));
  }
  return dir;
}

// A minimal 16-bit greyscale PNG (one IDAT, no filtering), so tests can make depth images with
// chosen values without an image library.
void writePng16(const fs::path& path, int width, int height,
                const std::function<std::uint16_t(int, int)>& value) {
  auto be32 = [](std::string& s, std::uint32_t v) {
    for (int i = 3; i >= 0; --i) s.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
  };
  auto chunk = [&](std::string& out, const char* type, const std::string& data) {
    be32(out, static_cast<std::uint32_t>(data.size()));
    const std::string body = std::string(type, 4) + data;
    out += body;
    be32(out, static_cast<std::uint32_t>(crc32(0, reinterpret_cast<const Bytef*>(body.data()),
                                               static_cast<uInt>(body.size()))));
  };
  std::string raw;
  for (int r = 0; r < height; ++r) {
    raw.push_back(0);  // filter: none
    for (int c = 0; c < width; ++c) {
      const std::uint16_t v = value(c, r);
      raw.push_back(static_cast<char>(v >> 8));
      raw.push_back(static_cast<char>(v & 0xff));
    }
  }
  uLongf packed_size = compressBound(static_cast<uLong>(raw.size()));
  std::string packed(packed_size, '\0');
  REQUIRE(compress(reinterpret_cast<Bytef*>(packed.data()), &packed_size,
                   reinterpret_cast<const Bytef*>(raw.data()),
                   static_cast<uLong>(raw.size())) == Z_OK);
  packed.resize(packed_size);
  std::string ihdr;
  be32(ihdr, static_cast<std::uint32_t>(width));
  be32(ihdr, static_cast<std::uint32_t>(height));
  ihdr +=
      std::string("\x10\x00\x00\x00\x00", 5);  // 16 bit, greyscale, deflate, no filter/interlace
  std::string png = "\x89PNG\r\n\x1a\n";
  chunk(png, "IHDR", ihdr);
  chunk(png, "IDAT", packed);
  chunk(png, "IEND", "");
  spit(path, png);
}

}  // namespace

// ---- real datasets end to end ----

TEST_CASE("TUM fr1/desk: 9 associated frames with interpolated ground truth and fr1 intrinsics",
          "[datasets][rgbd]") {
  TESSERA_SHARED_DATA(dir, kTum);
  REQUIRE(detectRgbdLayout(dir) == RgbdLayout::kTum);
  const RgbdSequence seq = readRgbdSequence(dir);
  REQUIRE(seq.layout == RgbdLayout::kTum);
  REQUIRE(seq.frames.size() == 9);
  CHECK(seq.unmatched_color == 0);
  CHECK(seq.depth_scale == 5000);
  CHECK(seq.color_registered);
  CHECK(seq.has_ground_truth);
  CHECK(seq.frames_without_pose == 0);
  CHECK(seq.intrinsics.fx == 517.3);
  CHECK(seq.intrinsics.cy == 255.3);
  CHECK(seq.intrinsics.distortion.size() == 5);
  CHECK_THAT(seq.intrinsics_source, Catch::Contains("freiburg1"));
  CHECK(seq.frames.front().timestamp == Approx(1305031453.359684).epsilon(1e-15));
  CHECK(seq.frames.back().timestamp == Approx(1305031453.627706).epsilon(1e-15));

  // Our pairing agrees with the associations.txt that comes with the folder.
  TumOptions from_file;
  from_file.use_associations_file = true;
  const RgbdSequence listed = readTumSequence(dir, from_file);
  REQUIRE(listed.frames.size() == 9);
  for (std::size_t i = 0; i < 9; ++i) {
    CHECK(seq.frames[i].color_path == listed.frames[i].color_path);
    CHECK(seq.frames[i].depth_path == listed.frames[i].depth_path);
    CHECK(std::abs(seq.frames[i].depth_timestamp - seq.frames[i].timestamp) < 0.02);
  }

  // Interpolated ground truth is within a few mm of the nearest raw sample (<= 4.2 ms away).
  TextReader gt_reader(dir / "groundtruth.txt");
  const auto truth = parseTumGroundTruth(gt_reader);
  CHECK(truth.size() == 2335);
  for (const auto& f : seq.frames) {
    REQUIRE(f.pose);
    checkRotation(*f.pose);
    const auto nearest = poseAt(truth, f.timestamp, 0, 0.005);
    REQUIRE(nearest);
    CHECK((f.pose->translation() - nearest->translation()).norm() < 0.01);
  }

  const auto t0 = std::chrono::steady_clock::now();
  for (std::size_t i = 0; i < seq.frames.size(); ++i) {
    INFO("frame " << i);
    const RgbdImages im = loadRgbdImages(seq, i);
    double med = 0, valid = 0;
    checkImages(im, med, valid);
    CHECK(im.depth_scale == 5000);
    CHECK(med > 0.5);
    CHECK(med < 4.0);
    CHECK(valid > 0.5);
  }
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count() / 9;
  std::cout << "TUM fr1/desk: 9 frames, " << ms << " ms per frame load\n";
}

TEST_CASE("7-Scenes RedKitchen: 450 frames at 30 Hz with orthonormal camera-to-world poses",
          "[datasets][rgbd]") {
  TESSERA_SHARED_DATA(dir, kSeven);
  REQUIRE(detectRgbdLayout(dir) == RgbdLayout::kSevenScenes);
  const RgbdSequence seq = readRgbdSequence(dir);
  REQUIRE(seq.layout == RgbdLayout::kSevenScenes);
  REQUIRE(seq.frames.size() == 450);
  CHECK(seq.depth_scale == 1000);
  CHECK_FALSE(seq.color_registered);
  CHECK(seq.has_ground_truth);
  CHECK(seq.frames_without_pose == 0);
  CHECK(seq.intrinsics.fx == 585);
  CHECK(seq.intrinsics.cx == 320);
  CHECK(seq.intrinsics.distortion.empty());
  for (std::size_t i = 0; i < seq.frames.size(); ++i) {
    const auto& f = seq.frames[i];
    CHECK(f.index == i);
    CHECK(f.timestamp == Approx(static_cast<double>(i) / 30.0));
    CHECK(f.color_path.extension() == ".jpg");
    REQUIRE(f.pose);
    checkRotation(*f.pose);
  }
  // Cross-check with the TUM-format copy of the poses that PROVENANCE.md describes.
  TextReader tum(dir / "groundtruth_tum.txt");
  const auto truth = parseTumGroundTruth(tum);
  REQUIRE(truth.size() == 450);
  for (std::size_t i = 0; i < 450; i += 7) {
    const Eigen::Isometry3d& T = *seq.frames[i].pose;
    CHECK((T.translation() - truth[i].position).norm() < 1e-6);
    CHECK(Eigen::Quaterniond(T.rotation()).angularDistance(truth[i].orientation) < 1e-3);
  }
  // Consecutive frames move at most a few cm (PROVENANCE: max 3.6 cm).
  for (std::size_t i = 1; i < 450; ++i)
    CHECK((seq.frames[i].pose->translation() - seq.frames[i - 1].pose->translation()).norm() <
          0.05);

  double total_ms = 0;
  int loaded = 0;
  for (std::size_t i = 0; i < seq.frames.size(); i += 15) {
    INFO("frame " << i);
    const auto t0 = std::chrono::steady_clock::now();
    const RgbdImages im = loadRgbdImages(seq, i);
    total_ms +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    ++loaded;
    double med = 0, valid = 0;
    checkImages(im, med, valid);
    CHECK(med > 0.5);
    CHECK(med < 4.0);
    CHECK(valid > 0.5);
  }
  std::cout << "7-Scenes RedKitchen: 450 frames indexed, " << total_ms / loaded
            << " ms per frame load (" << loaded << " sampled)\n";
}

// ---- layout, intrinsics, association, interpolation ----

TEST_CASE("RGB-D layout detection names what it looked for", "[datasets][rgbd]") {
  const auto empty = tessera::test::scratchDir("rgbd_empty");
  CHECK_THAT(errorOf([&] { detectRgbdLayout(empty); }),
             Catch::Contains("rgb.txt") && Catch::Contains("frame-NNNNNN.depth.png"));
  CHECK_THAT(errorOf([&] { detectRgbdLayout(empty / "nope"); }), Catch::Contains("not a folder"));
  CHECK(parseLayout("7scenes") == RgbdLayout::kSevenScenes);
  CHECK(parseLayout("TUM") == RgbdLayout::kTum);
  CHECK_THROWS_AS(parseLayout("kitti"), std::invalid_argument);
  CHECK(tumIntrinsics("fr2").fx == 520.9);
  CHECK(tumIntrinsics("freiburg3").distortion.empty());
  CHECK_THROWS_AS(tumIntrinsics("freiburg4"), std::invalid_argument);
}

TEST_CASE("TUM association pairs closest first, each image once, within a strict tolerance",
          "[datasets][rgbd]") {
  const std::vector<TimedFile> rgb = {{1.00, "a", 1}, {1.03, "b", 2}, {1.20, "c", 3}};
  const std::vector<TimedFile> depth = {{1.015, "x", 1}, {1.031, "y", 2}, {1.25, "z", 3}};
  std::size_t unmatched = 99;
  const auto pairs = associateTum(rgb, depth, 0.02, &unmatched);
  REQUIRE(pairs.size() == 2);
  // b-y (1 ms) is taken before a-x (15 ms); b is not paired with x although x is closer to a.
  CHECK(pairs[0].color.file == "a");
  CHECK(pairs[0].depth.file == "x");
  CHECK(pairs[1].color.file == "b");
  CHECK(pairs[1].depth.file == "y");
  CHECK(unmatched == 1);  // c: z is 50 ms away
  // A depth image shared by two colour candidates goes to the closer one only.
  const auto one = associateTum({{1.0, "a", 1}, {1.01, "b", 2}}, {{1.009, "x", 1}}, 0.02);
  REQUIRE(one.size() == 1);
  CHECK(one[0].color.file == "b");
  CHECK(associateTum({{1.0, "a", 1}}, {{1.02, "x", 1}}, 0.02).empty());  // strict <
}

TEST_CASE("Ground truth is interpolated between close samples, else nearest within tolerance",
          "[datasets][rgbd]") {
  std::vector<TimedPose> poses(3);
  poses[0].timestamp = 10.0;
  poses[1].timestamp = 10.01;
  poses[1].position = {1, 0, 0};
  poses[1].orientation = Eigen::Quaterniond(Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitZ()));
  poses[2].timestamp = 11.0;
  poses[2].position = {5, 0, 0};

  const auto mid = poseAt(poses, 10.005, 0.1, 0.02);
  REQUIRE(mid);
  CHECK(mid->translation().x() == Approx(0.5));
  CHECK(Eigen::AngleAxisd(mid->rotation()).angle() == Approx(0.1));
  // 10.02 lies in a 0.99 s gap: not interpolated; nearest (10.01) is 10 ms away.
  const auto near = poseAt(poses, 10.02, 0.1, 0.02);
  REQUIRE(near);
  CHECK(near->translation().x() == Approx(1.0));
  CHECK_FALSE(poseAt(poses, 10.5, 0.1, 0.02));  // far from both samples
  CHECK_FALSE(poseAt(poses, 9.9, 0.1, 0.02));   // before the first sample
  CHECK(poseAt(poses, 11.01, 0.1, 0.02));       // just after the last, within tolerance
  CHECK_FALSE(poseAt({}, 10.0, 0.1, 0.02));
}

// ---- malformed text files ----

TEST_CASE("Malformed rgb.txt / depth.txt lines throw naming file, line and field",
          "[datasets][rgbd]") {
  auto err = [](const std::string& text) {
    return parseError("rgb.txt", text, [](TextReader& r) { return parseTumFileList(r); });
  };
  CHECK(err("# header\n1.0 rgb/a.png\n\n2.0 rgb/b.png\n").empty());
  CHECK_THAT(err("1.0 rgb/a.png\n2.0\n"),
             Catch::Contains("rgb.txt:2") && Catch::Contains("expected 2 fields, got 1"));
  CHECK_THAT(err("1.0 rgb/a.png extra\n"), Catch::Contains("rgb.txt:1"));
  CHECK_THAT(err("nan rgb/a.png\n"), Catch::Contains("timestamp") && Catch::Contains("'nan'"));
  CHECK_THAT(err("inf rgb/a.png\n"), Catch::Contains("finite"));
  CHECK_THAT(err("1e999 rgb/a.png\n"), Catch::Contains("out of range"));
  CHECK_THAT(err("-1 rgb/a.png\n"), Catch::Contains("negative"));
  CHECK_THAT(err("2.0 rgb/a.png\n1.0 rgb/b.png\n"),
             Catch::Contains("rgb.txt:2") && Catch::Contains("not after"));
  CHECK_THAT(err("1.0 rgb/a.png\n1.0 rgb/b.png\n"), Catch::Contains("not after"));
  CHECK_THAT(err("x1.0 rgb/a.png\n"), Catch::Contains("expected a number"));
}

TEST_CASE("Malformed groundtruth.txt and associations.txt lines throw", "[datasets][rgbd]") {
  auto gt = [](const std::string& text) {
    return parseError("groundtruth.txt", text,
                      [](TextReader& r) { return parseTumGroundTruth(r); });
  };
  CHECK(gt("# t tx ty tz qx qy qz qw\n1 0 0 0 0 0 0 1\n2 1 2 3 0 0 0.7071 0.7071\n").empty());
  CHECK_THAT(gt("1 0 0 0 0 0 1\n"),
             Catch::Contains("groundtruth.txt:1") && Catch::Contains("expected 8 fields, got 7"));
  CHECK_THAT(gt("1 0 0 0 0 0 0 1 9\n"), Catch::Contains("expected 8 fields, got 9"));
  CHECK_THAT(gt("1 nan 0 0 0 0 0 1\n"), Catch::Contains("tx"));
  CHECK_THAT(gt("1 0 0 0 0 0 0 inf\n"), Catch::Contains("qw"));
  CHECK_THAT(gt("1 0 0 0 0 0 0 0\n"), Catch::Contains("norm 0"));
  CHECK_THAT(gt("1 0 0 0 0 0 0 2\n"), Catch::Contains("norm 2"));
  CHECK_THAT(gt("1 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n"),
             Catch::Contains("groundtruth.txt:2") && Catch::Contains("not after"));

  auto as = [](const std::string& text) {
    return parseError("associations.txt", text,
                      [](TextReader& r) { return parseTumAssociations(r); });
  };
  CHECK(as("1 rgb/a.png 1.01 depth/a.png\n").empty());
  CHECK_THAT(as("1 rgb/a.png 1.01\n"),
             Catch::Contains("associations.txt:1") && Catch::Contains("expected 4 fields, got 3"));
  CHECK_THAT(as("1 rgb/a.png nan depth/a.png\n"), Catch::Contains("depth timestamp"));
  CHECK_THAT(as("2 rgb/a.png 2 depth/a.png\n1 rgb/b.png 1 depth/b.png\n"),
             Catch::Contains("associations.txt:2"));
}

TEST_CASE("Malformed 7-Scenes pose and intrinsics files throw", "[datasets][rgbd]") {
  auto pose = [](const std::string& text) {
    return parseError("frame-000000.pose.txt", text,
                      [](TextReader& r) { return parseSevenScenesPose(r); });
  };
  const std::string ok = "1 0 0 0.5\n0 1 0 0\n0 0 1 0\n0 0 0 1\n";
  CHECK(pose(ok).empty());
  CHECK_THAT(pose("1 0 0 0.5\n0 1 0 0\n0 0 1 0\n"), Catch::Contains("expected 4 rows, got 3"));
  CHECK_THAT(pose(ok + "0 0 0 1\n"),
             Catch::Contains("pose.txt:5") && Catch::Contains("more than 4 rows"));
  CHECK_THAT(pose("1 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"),
             Catch::Contains("pose.txt:1") && Catch::Contains("expected 4 fields, got 3"));
  CHECK_THAT(pose("1 0 0 nan\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"), Catch::Contains("row 1 column 4"));
  CHECK_THAT(pose("1 0 0 -inf\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"), Catch::Contains("finite"));
  CHECK_THAT(pose("1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n"), Catch::Contains("0 0 0 1"));
  CHECK_THAT(pose("1 0.5 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"), Catch::Contains("orthonormal"));
  CHECK_THAT(pose("-1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"), Catch::Contains("determinant"));
  // Slightly off (printed precision) is accepted and returned exactly orthonormal.
  TextReader r = TextReader::fromString("p", "1 0.0004 0 0\n-0.0004 1 0 0\n0 0 1 0\n0 0 0 1\n");
  checkRotation(parseSevenScenesPose(r));

  auto k = [](const std::string& text) {
    return parseError("camera-intrinsics.txt", text,
                      [](TextReader& r) { return parseSevenScenesIntrinsics(r); });
  };
  CHECK(k("585 0 320\n0 585 240\n0 0 1\n").empty());
  CHECK_THAT(k("585 0 320\n0 585 240\n"), Catch::Contains("expected 3 rows, got 2"));
  CHECK_THAT(k("585 0 320\n0 585\n0 0 1\n"), Catch::Contains("camera-intrinsics.txt:2"));
  CHECK_THAT(k("585 1 320\n0 585 240\n0 0 1\n"), Catch::Contains("[fx 0 cx; 0 fy cy; 0 0 1]"));
  CHECK_THAT(k("-585 0 320\n0 585 240\n0 0 1\n"), Catch::Contains("focal"));
  CHECK_THAT(k("585 0 900\n0 585 240\n0 0 1\n"), Catch::Contains("principal point"));
  CHECK_THAT(k("585 0 nan\n0 585 240\n0 0 1\n"), Catch::Contains("row 1 column 3"));
}

// ---- missing and corrupt files ----

TEST_CASE("Missing TUM images and lists are errors naming the file, or counted skips",
          "[datasets][rgbd]") {
  TESSERA_SHARED_DATA(src, kTum);
  const fs::path dir = tumCopy(src, "rgbd_tum_missing");
  fs::remove(dir / "depth" / "1305031453.505218.png");
  CHECK_THAT(errorOf([&] { readTumSequence(dir); }), Catch::Contains("depth.txt:8") &&
                                                         Catch::Contains("1305031453.505218.png") &&
                                                         Catch::Contains("does not exist"));
  TumOptions skip;
  skip.skip_missing_images = true;
  const RgbdSequence seq = readTumSequence(dir, skip);
  CHECK(seq.frames.size() == 8);
  CHECK(seq.report.skipped == 1);
  CHECK(seq.report.skipped_by_reason.at("image file missing") == 1);

  fs::remove(dir / "rgb.txt");
  CHECK_THAT(errorOf([&] { readTumSequence(dir); }),
             Catch::Contains("rgb.txt") && Catch::Contains("cannot open"));
  // Ground truth is optional: without it frames simply carry no pose.
  const fs::path dir2 = tumCopy(src, "rgbd_tum_nogt");
  fs::remove(dir2 / "groundtruth.txt");
  const RgbdSequence no_gt = readTumSequence(dir2);
  CHECK_FALSE(no_gt.has_ground_truth);
  CHECK(no_gt.frames_without_pose == 9);
  // Nothing pairs when the tolerance is tiny.
  TumOptions tight;
  tight.max_time_difference = 1e-4;
  CHECK_THAT(errorOf([&] { readTumSequence(dir2, tight); }), Catch::Contains("no RGB-D frames"));
}

TEST_CASE("Missing 7-Scenes files are errors naming the frame", "[datasets][rgbd]") {
  TESSERA_SHARED_DATA(src, kSeven);
  const fs::path dir = sevenCopy(src, "rgbd_7s_missing", 4);
  CHECK(readSevenScenesSequence(dir).frames.size() == 4);
  fs::remove(dir / "frame-000002.pose.txt");
  CHECK_THAT(errorOf([&] { readSevenScenesSequence(dir); }),
             Catch::Contains("frame-000002.pose.txt") && Catch::Contains("missing"));
  fs::copy_file(src / "frame-000002.pose.txt", dir / "frame-000002.pose.txt");
  fs::remove(dir / "frame-000001.color.jpg");
  CHECK_THAT(errorOf([&] { readSevenScenesSequence(dir); }),
             Catch::Contains("frame-000001") && Catch::Contains("colour image"));
  fs::create_symlink(fs::absolute(src / "frame-000001.color.jpg"), dir / "frame-000001.color.jpg");
  // Without camera-intrinsics.txt the dataset's stated values are used.
  fs::remove(dir / "camera-intrinsics.txt");
  const RgbdSequence seq = readSevenScenesSequence(dir);
  CHECK(seq.intrinsics.fx == 585);
  CHECK_THAT(seq.intrinsics_source, Catch::Contains("stated"));
  // A stray file name is counted, not silently ignored.
  spit(dir / "frame-x.depth.png", "");
  CHECK(readSevenScenesSequence(dir).report.skipped == 1);
  SevenScenesOptions bad_fps;
  bad_fps.fps = 0;
  CHECK_THAT(errorOf([&] { readSevenScenesSequence(dir, bad_fps); }), Catch::Contains("fps"));
}

TEST_CASE("Truncated, corrupt or wrong-type images throw naming the image file",
          "[datasets][rgbd]") {
  TESSERA_SHARED_DATA(tum_src, kTum);
  TESSERA_SHARED_DATA(seven_src, kSeven);
  const fs::path dir = sevenCopy(seven_src, "rgbd_7s_corrupt", 1);
  const std::string jpg = slurp(seven_src / "frame-000000.color.jpg");
  const std::string png = slurp(seven_src / "frame-000000.depth.png");
  const fs::path color = dir / "frame-000000.color.jpg";
  const fs::path depth = dir / "frame-000000.depth.png";
  auto reset = [&] {
    fs::remove(color);
    fs::remove(depth);
    spit(color, jpg);
    spit(depth, png);
  };
  auto loadError = [&] {
    const RgbdSequence seq = readSevenScenesSequence(dir);
    return errorOf([&] { (void)loadRgbdImages(seq, 0); });
  };
  reset();
  CHECK(loadError().empty());

  spit(color, jpg.substr(0, jpg.size() / 2));
  CHECK_THAT(loadError(),
             Catch::Contains("frame-000000.color.jpg") && Catch::Contains("truncated JPEG"));
  reset();
  spit(depth, png.substr(0, png.size() - 100));
  CHECK_THAT(loadError(),
             Catch::Contains("frame-000000.depth.png") && Catch::Contains("truncated PNG"));
  reset();
  std::string broken = png;
  for (std::size_t i = 200; i < 400; ++i) broken[i] = static_cast<char>(broken[i] ^ 0x5a);
  spit(depth, broken);  // complete container, corrupt data (CRC / zlib errors)
  CHECK_THAT(loadError(),
             Catch::Contains("frame-000000.depth.png") && Catch::Contains("cannot decode"));
  reset();
  spit(depth, "");
  CHECK_THAT(loadError(), Catch::Contains("empty"));
  reset();
  spit(depth, "not an image at all");
  CHECK_THAT(loadError(), Catch::Contains("cannot decode"));
  reset();
  // An 8-bit colour PNG where 16-bit depth is expected.
  const fs::path tum_rgb = *fs::directory_iterator(tum_src / "rgb");
  spit(depth, slurp(tum_rgb));
  CHECK_THAT(loadError(), Catch::Contains("16-bit") && Catch::Contains("3-channel 8U"));
  reset();
  // Images of another size than the intrinsics say.
  spit(dir / "camera-intrinsics.txt", "585 0 100\n0 585 100\n0 0 1\n");
  RgbdSequence seq = readSevenScenesSequence(dir);
  seq.intrinsics.width = 320;
  CHECK_THAT(errorOf([&] { (void)loadRgbdImages(seq, 0); }),
             Catch::Contains("640x480") && Catch::Contains("320x480"));
  CHECK_THROWS_AS(loadRgbdImages(seq, 5), std::out_of_range);
  fs::remove(color);
  CHECK_THAT(errorOf([&] { (void)loadRgbdImages(seq, 0); }),
             Catch::Contains("frame-000000.color.jpg") && Catch::Contains("does not exist"));
}

TEST_CASE("7-Scenes depth 65535 loads as no reading; TUM keeps 16-bit values as they are",
          "[datasets][rgbd]") {
  RgbdImages im;
  im.width = 3;
  im.height = 1;
  im.depth = {0, 1500, 40000};
  im.depth_scale = 1000;
  const auto m = depthInMetres(im);
  CHECK(std::isnan(m[0]));
  CHECK(m[1] == Approx(1.5f));
  CHECK(m[2] == Approx(40.0f));

  TESSERA_SHARED_DATA(src, kSeven);
  const fs::path dir = sevenCopy(src, "rgbd_7s_invalid", 1);
  fs::remove(dir / "frame-000000.depth.png");
  // Column 0 invalid (65535), column 1 no reading (0), elsewhere 1.234 m.
  writePng16(dir / "frame-000000.depth.png", 640, 480, [](int c, int) -> std::uint16_t {
    return c == 0 ? 65535 : c == 1 ? 0 : 1234;
  });
  RgbdSequence seq = readSevenScenesSequence(dir);
  const RgbdImages loaded = loadRgbdImages(seq, 0);
  CHECK(loaded.depth[0] == 0);
  CHECK(loaded.depth[1] == 0);
  CHECK(loaded.depth[2] == 1234);
  CHECK(loaded.depth[640 * 479] == 0);
  CHECK(depthInMetres(loaded)[5] == Approx(1.234f));
  seq.layout = RgbdLayout::kTum;  // the rewrite is 7-Scenes' convention only
  CHECK(loadRgbdImages(seq, 0).depth[0] == 65535);

  // A depth image of the wrong size names both sizes.
  fs::remove(dir / "frame-000000.depth.png");
  writePng16(dir / "frame-000000.depth.png", 320, 240, [](int, int) { return 1000; });
  CHECK_THAT(errorOf([&] { (void)loadRgbdImages(readSevenScenesSequence(dir), 0); }),
             Catch::Contains("frame-000000.depth.png") && Catch::Contains("320x240") &&
                 Catch::Contains("640x480"));
}

// ---- mutation property test ----

namespace {

// Runs f; only success or DatasetError are acceptable outcomes.
template <typename F>
void succeedsOrDatasetError(F&& f, const std::string& what, std::size_t& failures,
                            std::size_t& errors) {
  try {
    f();
  } catch (const DatasetError&) {
    ++errors;
  } catch (const std::exception& e) {
    ++failures;
    FAIL_CHECK(what << ": threw something else than DatasetError: " << e.what());
  } catch (...) {
    ++failures;
    FAIL_CHECK(what << ": threw a non-exception");
  }
}

}  // namespace

TEST_CASE("Mutated RGB-D text files either parse or throw DatasetError, never anything else",
          "[datasets][rgbd][fuzz]") {
  TESSERA_SHARED_DATA(tum, kTum);
  TESSERA_SHARED_DATA(seven, kSeven);
  tessera::test::Mutator mutator(20240611);
  std::size_t failures = 0, errors = 0, runs = 0;

  // In memory, every parser on its own file.
  struct Case {
    std::string name, text;
    std::function<void(TextReader&)> parse;
  };
  std::string gt_head;  // first 300 lines keep the loop fast; the full file is parsed above
  {
    std::istringstream in(slurp(tum / "groundtruth.txt"));
    std::string line;
    for (int i = 0; i < 300 && std::getline(in, line); ++i) gt_head += line + "\n";
  }
  const std::vector<Case> cases = {
      {"rgb.txt", slurp(tum / "rgb.txt"), [](TextReader& r) { (void)parseTumFileList(r); }},
      {"depth.txt", slurp(tum / "depth.txt"), [](TextReader& r) { (void)parseTumFileList(r); }},
      {"associations.txt", slurp(tum / "associations.txt"),
       [](TextReader& r) { (void)parseTumAssociations(r); }},
      {"groundtruth.txt", gt_head, [](TextReader& r) { (void)parseTumGroundTruth(r); }},
      {"frame-000000.pose.txt", slurp(seven / "frame-000000.pose.txt"),
       [](TextReader& r) { (void)parseSevenScenesPose(r); }},
      {"camera-intrinsics.txt", slurp(seven / "camera-intrinsics.txt"),
       [](TextReader& r) { (void)parseSevenScenesIntrinsics(r); }},
  };
  for (const auto& c : cases) {
    for (int i = 0; i < 400; ++i) {
      const std::string text = mutator.mutate(c.text);
      succeedsOrDatasetError(
          [&] {
            TextReader r = TextReader::fromString(c.name, text);
            c.parse(r);
          },
          c.name, failures, errors);
      ++runs;
    }
  }

  // Whole folders: association, ground-truth lookup and file checks on mutated lists.
  const fs::path tdir = tumCopy(tum, "rgbd_fuzz_tum");
  const std::vector<std::string> tum_files = {"rgb.txt", "depth.txt", "associations.txt",
                                              "groundtruth.txt"};
  std::map<std::string, std::string> originals;
  for (const auto& f : tum_files) originals[f] = slurp(tdir / f);
  for (int i = 0; i < 120; ++i) {
    const std::string& f = tum_files[static_cast<std::size_t>(i) % tum_files.size()];
    spit(tdir / f, mutator.mutate(originals[f]));
    TumOptions o;
    o.use_associations_file = f == "associations.txt";
    succeedsOrDatasetError([&] { (void)readTumSequence(tdir, o); }, "TUM folder, " + f, failures,
                           errors);
    spit(tdir / f, originals[f]);
    ++runs;
  }
  const fs::path sdir = sevenCopy(seven, "rgbd_fuzz_7s", 3);
  const std::vector<std::string> seven_files = {"frame-000001.pose.txt", "camera-intrinsics.txt"};
  for (const auto& f : seven_files) originals[f] = slurp(sdir / f);
  for (int i = 0; i < 60; ++i) {
    const std::string& f = seven_files[static_cast<std::size_t>(i) % seven_files.size()];
    spit(sdir / f, mutator.mutate(originals[f]));
    succeedsOrDatasetError([&] { (void)readSevenScenesSequence(sdir); }, "7-Scenes folder, " + f,
                           failures, errors);
    spit(sdir / f, originals[f]);
    ++runs;
  }
  CHECK(failures == 0);
  // The mutations must actually hurt: most runs end in a DatasetError.
  CHECK(errors > runs / 2);
  std::cout << "RGB-D text mutation test: " << runs << " runs, " << errors << " DatasetErrors, "
            << failures << " other outcomes\n";
}
