// RGB-D sequences (tessera/datasets/rgbd_sequence.hpp): the TUM RGB-D and 7-Scenes folder layouts,
// their text files, intrinsics and poses, and loading a frame's images. Longer than ~600 lines on
// purpose: both layouts produce the same RgbdSequence through the same field and file checks.
#include <tessera/datasets/rgbd_sequence.hpp>

#include <tessera/io/image_file.hpp>

#include <Eigen/SVD>

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>
#include <tuple>

namespace tessera::datasets {

using io::DatasetError;
using io::Fields;
using io::TextReader;
namespace fs = std::filesystem;

namespace {

std::string str(double v) {
  std::ostringstream s;
  s.precision(17);
  s << v;
  return s.str();
}

std::string lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

bool isData(const std::string& line) {
  const auto first = line.find_first_not_of(" \t\r");
  return first != std::string::npos && line[first] != '#';
}

bool isFile(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec);
}

// A timestamp: finite, not negative (TUM uses Unix time, 7-Scenes none).
double timestampField(const Fields& f, std::size_t i, std::string_view label) {
  const double t = f.real(i, label);
  if (t < 0)
    f.fail("field " + std::to_string(i + 1) + " (" + std::string(label) + "): negative timestamp " +
           str(t));
  return t;
}

std::string fileField(const Fields& f, std::size_t i, std::string_view label) {
  std::string name(f[i]);
  if (name.find('\0') != std::string::npos)
    f.fail("field " + std::to_string(i + 1) + " (" + std::string(label) +
           "): file name contains a NUL byte");
  return name;
}

}  // namespace

// ---- layout ----

std::string_view layoutName(RgbdLayout layout) {
  return layout == RgbdLayout::kTum ? "tum" : "7scenes";
}

RgbdLayout parseLayout(std::string_view name) {
  const std::string n = lower(name);
  if (n == "tum") return RgbdLayout::kTum;
  if (n == "7scenes" || n == "sevenscenes" || n == "7-scenes") return RgbdLayout::kSevenScenes;
  throw std::invalid_argument("unknown RGB-D layout '" + std::string(name) +
                              "', expected tum or 7scenes");
}

namespace {
// frame-NNNNNN.<kind>; returns the frame number or -1.
std::int64_t sevenScenesIndex(const std::string& name, std::string_view suffix) {
  constexpr std::string_view kPrefix = "frame-";
  if (!name.starts_with(kPrefix) || !name.ends_with(suffix)) return -1;
  const std::string_view digits(name.data() + kPrefix.size(),
                                name.size() - kPrefix.size() - suffix.size());
  if (digits.empty() || digits.size() > 9) return -1;
  std::int64_t v = 0;
  const auto [ptr, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), v);
  if (ec != std::errc() || ptr != digits.data() + digits.size() || digits.front() == '-') return -1;
  return v;
}
}  // namespace

RgbdLayout detectRgbdLayout(const fs::path& folder) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) throw DatasetError(folder, 0, "not a folder");
  if (isFile(folder / "rgb.txt") && isFile(folder / "depth.txt")) return RgbdLayout::kTum;
  if (isFile(folder / "associations.txt")) return RgbdLayout::kTum;
  for (fs::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec)) {
    if (sevenScenesIndex(it->path().filename().string(), ".depth.png") >= 0)
      return RgbdLayout::kSevenScenes;
  }
  throw DatasetError(folder, 0,
                     "not an RGB-D dataset folder: found neither rgb.txt + depth.txt (TUM RGB-D) "
                     "nor frame-NNNNNN.depth.png files (7-Scenes)");
}

// ---- intrinsics ----

CameraIntrinsics tumIntrinsics(std::string_view camera) {
  const std::string c = lower(camera);
  CameraIntrinsics k;
  k.width = 640;
  k.height = 480;
  if (c == "freiburg1" || c == "fr1") {
    k.fx = 517.3, k.fy = 516.5, k.cx = 318.6, k.cy = 255.3;
    k.distortion = {0.2624, -0.9531, -0.0054, 0.0026, 1.1633};
  } else if (c == "freiburg2" || c == "fr2") {
    k.fx = 520.9, k.fy = 521.0, k.cx = 325.1, k.cy = 249.7;
    k.distortion = {0.2312, -0.7849, -0.0033, -0.0001, 0.9172};
  } else if (c == "freiburg3" || c == "fr3") {
    k.fx = 535.4, k.fy = 539.2, k.cx = 320.1, k.cy = 247.6;  // fr3 images are undistorted
  } else if (c == "ros_default") {
    k.fx = 525.0, k.fy = 525.0, k.cx = 319.5, k.cy = 239.5;
  } else {
    throw std::invalid_argument("unknown TUM camera '" + std::string(camera) +
                                "', expected freiburg1, freiburg2, freiburg3 or ros_default");
  }
  return k;
}

namespace {

// "freiburg1".. from text such as "rgbd_dataset_freiburg1_desk" or "tum-rgbd-fr1-desk"; "" if
// none or ambiguous.
std::string cameraFromText(const std::string& text) {
  const std::string t = lower(text);
  std::string found;
  for (const char* digit : {"1", "2", "3"}) {
    const std::string long_name = std::string("freiburg") + digit;
    bool hit = t.find(long_name) != std::string::npos;
    // "fr1" only as a word of its own ("tum-rgbd-fr1-desk"), not inside another word.
    const std::string short_name = std::string("fr") + digit;
    for (std::size_t p = t.find(short_name); !hit && p != std::string::npos;
         p = t.find(short_name, p + 1)) {
      const bool left = p == 0 || !std::isalnum(static_cast<unsigned char>(t[p - 1]));
      const std::size_t e = p + short_name.size();
      const bool right = e == t.size() || !std::isalnum(static_cast<unsigned char>(t[e]));
      hit = left && right;
    }
    if (hit) {
      if (!found.empty()) return "";
      found = long_name;
    }
  }
  return found;
}

std::pair<std::string, std::string> chooseTumCamera(const fs::path& folder,
                                                    const TumOptions& options) {
  if (lower(options.camera) != "auto") {
    (void)tumIntrinsics(options.camera);  // validates the name
    return {lower(options.camera), "TUM " + lower(options.camera) + " (set by option)"};
  }
  // The TUM lists start with "# file: 'rgbd_dataset_freiburg1_desk.bag'".
  for (const char* list : {"rgb.txt", "depth.txt"}) {
    if (!isFile(folder / list)) continue;
    TextReader reader(folder / list);
    std::string line;
    while (reader.next(line) && !isData(line)) {
      const std::string cam = cameraFromText(line);
      if (!cam.empty()) return {cam, "TUM " + cam + " (from the header of " + list + ")"};
    }
  }
  fs::path abs = folder;
  std::error_code ec;
  if (auto a = fs::weakly_canonical(folder, ec); !ec) abs = a;
  const std::string cam = cameraFromText(abs.filename().string());
  if (!cam.empty()) return {cam, "TUM " + cam + " (from the folder name)"};
  throw DatasetError(folder, 0,
                     "cannot tell which TUM camera recorded this sequence (no freiburg1/2/3 in "
                     "rgb.txt's header or the folder name); set the camera option");
}

}  // namespace

// ---- TUM text files ----

std::vector<TimedFile> parseTumFileList(TextReader& reader) {
  std::vector<TimedFile> out;
  std::string line;
  double last = -1;
  while (reader.next(line)) {
    if (!isData(line)) continue;
    Fields f(reader, line);
    f.requireExactly(2, "timestamp filename");
    TimedFile tf{timestampField(f, 0, "timestamp"), fileField(f, 1, "filename"),
                 reader.lineNumber()};
    if (tf.timestamp <= last)
      f.fail("timestamp " + str(tf.timestamp) + " is not after the previous one (" + str(last) +
             ")");
    last = tf.timestamp;
    out.push_back(std::move(tf));
  }
  return out;
}

std::vector<TumAssociation> parseTumAssociations(TextReader& reader) {
  std::vector<TumAssociation> out;
  std::string line;
  double last = -1;
  while (reader.next(line)) {
    if (!isData(line)) continue;
    Fields f(reader, line);
    f.requireExactly(4, "rgb_timestamp rgb_file depth_timestamp depth_file");
    TumAssociation a;
    a.color = {timestampField(f, 0, "rgb timestamp"), fileField(f, 1, "rgb file"),
               reader.lineNumber()};
    a.depth = {timestampField(f, 2, "depth timestamp"), fileField(f, 3, "depth file"),
               reader.lineNumber()};
    if (a.color.timestamp <= last)
      f.fail("rgb timestamp " + str(a.color.timestamp) + " is not after the previous one (" +
             str(last) + ")");
    last = a.color.timestamp;
    out.push_back(std::move(a));
  }
  return out;
}

std::vector<TimedPose> parseTumGroundTruth(TextReader& reader) {
  std::vector<TimedPose> out;
  std::string line;
  double last = -1;
  while (reader.next(line)) {
    if (!isData(line)) continue;
    Fields f(reader, line);
    f.requireExactly(8, "timestamp tx ty tz qx qy qz qw");
    TimedPose p;
    p.timestamp = timestampField(f, 0, "timestamp");
    if (p.timestamp <= last)
      f.fail("timestamp " + str(p.timestamp) + " is not after the previous one (" + str(last) +
             ")");
    last = p.timestamp;
    p.position = {f.real(1, "tx"), f.real(2, "ty"), f.real(3, "tz")};
    const Eigen::Quaterniond q(f.real(7, "qw"), f.real(4, "qx"), f.real(5, "qy"), f.real(6, "qz"));
    const double n = q.norm();
    if (!(std::abs(n - 1) <= 1e-2))
      f.fail("quaternion (qx qy qz qw) has norm " + str(n) + ", expected 1");
    p.orientation = q.normalized();
    out.push_back(p);
  }
  return out;
}

std::vector<TumAssociation> associateTum(const std::vector<TimedFile>& color,
                                         const std::vector<TimedFile>& depth,
                                         double max_time_difference, std::size_t* unmatched_color) {
  // Candidate pairs closer than the tolerance, found by a window search on the sorted depth
  // times, then taken closest first so each image ends up in at most one pair.
  std::vector<std::tuple<double, std::size_t, std::size_t>> candidates;
  std::vector<double> depth_t(depth.size());
  for (std::size_t j = 0; j < depth.size(); ++j) depth_t[j] = depth[j].timestamp;
  for (std::size_t i = 0; i < color.size(); ++i) {
    const double t = color[i].timestamp;
    auto j = static_cast<std::size_t>(
        std::lower_bound(depth_t.begin(), depth_t.end(), t - max_time_difference) -
        depth_t.begin());
    for (; j < depth_t.size() && depth_t[j] <= t + max_time_difference; ++j) {
      const double d = std::abs(depth_t[j] - t);
      if (d < max_time_difference) candidates.emplace_back(d, i, j);
    }
  }
  std::sort(candidates.begin(), candidates.end());
  std::vector<char> color_used(color.size(), 0), depth_used(depth.size(), 0);
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  for (const auto& [d, i, j] : candidates) {
    if (color_used[i] || depth_used[j]) continue;
    color_used[i] = depth_used[j] = 1;
    pairs.emplace_back(i, j);
  }
  std::sort(pairs.begin(), pairs.end());
  std::vector<TumAssociation> out;
  out.reserve(pairs.size());
  for (const auto& [i, j] : pairs) out.push_back({color[i], depth[j]});
  if (unmatched_color) *unmatched_color = color.size() - pairs.size();
  return out;
}

std::optional<Eigen::Isometry3d> poseAt(const std::vector<TimedPose>& poses, double t,
                                        double max_interpolation_gap,
                                        double max_pose_time_difference) {
  if (poses.empty()) return std::nullopt;
  const auto after = std::upper_bound(poses.begin(), poses.end(), t,
                                      [](double v, const TimedPose& p) { return v < p.timestamp; });
  const TimedPose* b = after == poses.end() ? nullptr : &*after;
  const TimedPose* a = after == poses.begin() ? nullptr : &*(after - 1);
  auto iso = [](const Eigen::Vector3d& p, const Eigen::Quaterniond& q) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = q.toRotationMatrix();
    T.translation() = p;
    return T;
  };
  if (a && b && b->timestamp - a->timestamp <= max_interpolation_gap) {
    const double s = (t - a->timestamp) / (b->timestamp - a->timestamp);
    return iso(a->position + s * (b->position - a->position),
               a->orientation.slerp(s, b->orientation).normalized());
  }
  const TimedPose* nearest = nullptr;
  if (a && b)
    nearest = (t - a->timestamp <= b->timestamp - t) ? a : b;
  else
    nearest = a ? a : b;
  if (std::abs(nearest->timestamp - t) <= max_pose_time_difference)
    return iso(nearest->position, nearest->orientation);
  return std::nullopt;
}

RgbdSequence readTumSequence(const fs::path& folder, const TumOptions& options) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) throw DatasetError(folder, 0, "not a folder");
  if (!(options.max_time_difference > 0) || !std::isfinite(options.max_time_difference))
    throw DatasetError(
        folder, 0, "max_time_difference must be > 0 s, got " + str(options.max_time_difference));
  if (!(options.max_interpolation_gap >= 0) || !(options.max_pose_time_difference >= 0))
    throw DatasetError(folder, 0, "ground-truth time tolerances must be >= 0");

  RgbdSequence seq;
  seq.layout = RgbdLayout::kTum;
  seq.folder = folder;
  seq.depth_scale = 5000;  // TUM: "depth images are scaled by a factor of 5000"
  seq.color_registered = true;
  try {
    const auto [camera, source] = chooseTumCamera(folder, options);
    seq.intrinsics = tumIntrinsics(camera);
    seq.intrinsics_source = source;
  } catch (const std::invalid_argument& e) {
    throw DatasetError(folder, 0, e.what());
  }

  std::vector<TumAssociation> pairs;
  std::string list_name;
  if (options.use_associations_file) {
    TextReader reader(folder / "associations.txt");
    pairs = parseTumAssociations(reader);
    seq.report.lines += reader.lineNumber();
    list_name = "associations.txt";
  } else {
    TextReader rgb(folder / "rgb.txt");
    TextReader depth(folder / "depth.txt");
    const auto color_list = parseTumFileList(rgb);
    const auto depth_list = parseTumFileList(depth);
    seq.report.lines += rgb.lineNumber() + depth.lineNumber();
    pairs = associateTum(color_list, depth_list, options.max_time_difference, &seq.unmatched_color);
    list_name = "rgb.txt";
  }

  std::vector<TimedPose> truth;
  if (isFile(folder / "groundtruth.txt")) {
    TextReader reader(folder / "groundtruth.txt");
    truth = parseTumGroundTruth(reader);
    seq.report.lines += reader.lineNumber();
    seq.has_ground_truth = !truth.empty();
  }

  for (const auto& pair : pairs) {
    RgbdFrameInfo frame;
    frame.timestamp = pair.color.timestamp;
    frame.depth_timestamp = pair.depth.timestamp;
    frame.color_path = folder / pair.color.file;
    frame.depth_path = folder / pair.depth.file;
    bool missing = false;
    for (const auto& [path, entry, list] :
         {std::tuple{frame.color_path, &pair.color, list_name},
          std::tuple{frame.depth_path, &pair.depth,
                     options.use_associations_file ? list_name : std::string("depth.txt")}}) {
      if (isFile(path)) continue;
      if (!options.skip_missing_images)
        throw DatasetError(folder / list, entry->line,
                           "image '" + entry->file + "' does not exist (" + path.string() + ")");
      seq.report.skip(folder / list, entry->line, "image file missing");
      missing = true;
      break;
    }
    if (missing) continue;
    frame.index = seq.frames.size();
    frame.pose = poseAt(truth, frame.timestamp, options.max_interpolation_gap,
                        options.max_pose_time_difference);
    if (!frame.pose) ++seq.frames_without_pose;
    seq.frames.push_back(std::move(frame));
  }
  seq.report.records = seq.frames.size();
  if (seq.frames.empty())
    throw DatasetError(folder, 0,
                       "no RGB-D frames: no colour image has a depth image within " +
                           str(options.max_time_difference) + " s (or the lists are empty)");
  return seq;
}

// ---- 7-Scenes ----

namespace {
// Rows of numbers of a small matrix file; every data line must hold exactly `cols` numbers.
Eigen::MatrixXd readMatrix(TextReader& reader, int rows, int cols, std::string_view what) {
  Eigen::MatrixXd m(rows, cols);
  std::string line;
  int r = 0;
  while (reader.next(line)) {
    if (!isData(line)) continue;
    if (r == rows) reader.fail(std::string(what) + ": more than " + std::to_string(rows) + " rows");
    Fields f(reader, line);
    f.requireExactly(static_cast<std::size_t>(cols), std::string(what) + " row");
    for (int c = 0; c < cols; ++c)
      m(r, c) = f.real(static_cast<std::size_t>(c),
                       "row " + std::to_string(r + 1) + " column " + std::to_string(c + 1));
    ++r;
  }
  if (r < rows)
    throw DatasetError(reader.path(), reader.lineNumber(),
                       std::string(what) + ": expected " + std::to_string(rows) + " rows, got " +
                           std::to_string(r));
  return m;
}
}  // namespace

Eigen::Isometry3d parseSevenScenesPose(TextReader& reader) {
  const Eigen::MatrixXd m = readMatrix(reader, 4, 4, "4x4 pose");
  auto fail = [&](const std::string& msg) { throw DatasetError(reader.path(), 0, msg); };
  if ((m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-6)
    fail("last row of the pose must be 0 0 0 1");
  const Eigen::Matrix3d R = m.topLeftCorner<3, 3>();
  const double err = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (!(err <= 1e-2)) fail("rotation is not orthonormal (max |R^T R - I| = " + str(err) + ")");
  if (!(R.determinant() > 0)) fail("rotation has determinant " + str(R.determinant()) + " <= 0");
  // Nearest rotation, so downstream code gets an exact SO(3) element.
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = svd.matrixU() * svd.matrixV().transpose();
  T.translation() = m.topRightCorner<3, 1>();
  return T;
}

CameraIntrinsics parseSevenScenesIntrinsics(TextReader& reader) {
  const Eigen::MatrixXd K = readMatrix(reader, 3, 3, "3x3 camera matrix");
  auto fail = [&](const std::string& msg) { throw DatasetError(reader.path(), 0, msg); };
  CameraIntrinsics k;
  k.width = 640;
  k.height = 480;
  k.fx = K(0, 0), k.fy = K(1, 1), k.cx = K(0, 2), k.cy = K(1, 2);
  if (K(0, 1) != 0 || K(1, 0) != 0 || K(2, 0) != 0 || K(2, 1) != 0 || K(2, 2) != 1)
    fail("camera matrix must be [fx 0 cx; 0 fy cy; 0 0 1]");
  if (!(k.fx > 0 && k.fy > 0 && k.fx < 1e5 && k.fy < 1e5))
    fail("focal lengths must be positive pixels, got fx " + str(k.fx) + ", fy " + str(k.fy));
  if (!(k.cx > 0 && k.cx < k.width && k.cy > 0 && k.cy < k.height))
    fail("principal point (" + str(k.cx) + ", " + str(k.cy) + ") is outside the 640x480 image");
  return k;
}

RgbdSequence readSevenScenesSequence(const fs::path& folder, const SevenScenesOptions& options) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) throw DatasetError(folder, 0, "not a folder");
  if (!(options.fps > 0) || !std::isfinite(options.fps))
    throw DatasetError(folder, 0, "fps must be > 0, got " + str(options.fps));

  RgbdSequence seq;
  seq.layout = RgbdLayout::kSevenScenes;
  seq.folder = folder;
  seq.depth_scale = 1000;  // millimetres
  seq.color_registered = false;

  const fs::path intrinsics_file = folder / "camera-intrinsics.txt";
  if (isFile(intrinsics_file)) {
    TextReader reader(intrinsics_file);
    seq.intrinsics = parseSevenScenesIntrinsics(reader);
    seq.intrinsics_source = "camera-intrinsics.txt (depth camera)";
  } else {
    seq.intrinsics.fx = seq.intrinsics.fy = 585;
    seq.intrinsics.cx = 320;
    seq.intrinsics.cy = 240;
    seq.intrinsics.width = 640;
    seq.intrinsics.height = 480;
    seq.intrinsics_source = "7-Scenes stated depth camera (585, 585, 320, 240)";
  }

  std::map<std::int64_t, std::string> depth_files;  // sorted by frame number
  std::size_t poses_found = 0;
  fs::directory_iterator it(folder, ec);
  if (ec) throw DatasetError(folder, 0, "cannot list the folder: " + ec.message());
  for (fs::directory_iterator end; it != end; it.increment(ec)) {
    if (ec) throw DatasetError(folder, 0, "cannot list the folder: " + ec.message());
    const std::string name = it->path().filename().string();
    if (name.ends_with(".pose.txt") && sevenScenesIndex(name, ".pose.txt") >= 0) ++poses_found;
    if (!name.ends_with(".depth.png")) continue;
    const std::int64_t index = sevenScenesIndex(name, ".depth.png");
    if (index < 0) {
      seq.report.skip(folder / name, 0, "depth file name is not frame-NNNNNN.depth.png");
      continue;
    }
    if (!depth_files.emplace(index, name).second)
      throw DatasetError(
          folder / name, 0,
          "frame " + std::to_string(index) + " appears twice (also as " + depth_files[index] + ")");
  }
  seq.has_ground_truth = poses_found > 0;

  for (const auto& [index, depth_name] : depth_files) {
    const std::string stem = depth_name.substr(0, depth_name.size() - std::strlen(".depth.png"));
    RgbdFrameInfo frame;
    frame.index = static_cast<std::size_t>(index);
    frame.timestamp = frame.depth_timestamp = static_cast<double>(index) / options.fps;
    frame.depth_path = folder / depth_name;
    for (const char* ext : {".color.png", ".color.jpg"}) {
      if (isFile(folder / (stem + ext))) {
        frame.color_path = folder / (stem + ext);
        break;
      }
    }
    if (frame.color_path.empty())
      throw DatasetError(folder / (stem + ".color.png"), 0,
                         "colour image of frame " + std::to_string(index) +
                             " is missing (looked for .color.png and .color.jpg)");
    const fs::path pose_file = folder / (stem + ".pose.txt");
    if (isFile(pose_file)) {
      TextReader reader(pose_file);
      frame.pose = parseSevenScenesPose(reader);
      seq.report.lines += reader.lineNumber();
    } else if (seq.has_ground_truth) {
      throw DatasetError(
          pose_file, 0,
          "pose of frame " + std::to_string(index) + " is missing while other frames have one");
    } else {
      ++seq.frames_without_pose;
    }
    seq.frames.push_back(std::move(frame));
  }
  seq.report.records = seq.frames.size();
  if (seq.frames.empty())
    throw DatasetError(folder, 0, "no frame-NNNNNN.depth.png files: not a 7-Scenes folder");
  return seq;
}

RgbdSequence readRgbdSequence(const fs::path& folder, const RgbdReadOptions& options) {
  const RgbdLayout layout = options.layout ? *options.layout : detectRgbdLayout(folder);
  return layout == RgbdLayout::kTum ? readTumSequence(folder, options.tum)
                                    : readSevenScenesSequence(folder, options.seven_scenes);
}

// ---- images ----

namespace {

std::vector<unsigned char> readBytes(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw DatasetError(path, 0, "image file does not exist");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw DatasetError(path, 0, "cannot open image file");
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size <= 0) throw DatasetError(path, 0, "image file is empty");
  if (size > (std::streamoff{1} << 30)) throw DatasetError(path, 0, "image file larger than 1 GiB");
  in.seekg(0);
  std::vector<unsigned char> bytes(static_cast<std::size_t>(size));
  in.read(reinterpret_cast<char*>(bytes.data()), size);
  if (in.gcount() != size) throw DatasetError(path, 0, "cannot read image file");
  return bytes;
}

// Decoders fill what a truncated file lacks (libjpeg warns and pads with grey), so completeness
// is checked from the container: a PNG ends with its IEND chunk, a JPEG with the EOI marker.
void checkComplete(const fs::path& path, const std::vector<unsigned char>& b) {
  static constexpr std::array<unsigned char, 8> kPng = {0x89, 'P',  'N',  'G',
                                                        '\r', '\n', 0x1a, '\n'};
  static constexpr std::array<unsigned char, 8> kIend = {'I',  'E',  'N',  'D',
                                                         0xae, 0x42, 0x60, 0x82};
  if (b.size() >= kPng.size() && std::equal(kPng.begin(), kPng.end(), b.begin())) {
    if (b.size() < 8 + 12 || !std::equal(kIend.begin(), kIend.end(), b.end() - 8))
      throw DatasetError(path, 0, "truncated PNG (no IEND chunk at the end)");
    return;
  }
  if (b.size() >= 3 && b[0] == 0xff && b[1] == 0xd8 && b[2] == 0xff) {
    // Some writers pad after EOI; accept up to 64 trailing bytes.
    const std::size_t from = b.size() > 66 ? b.size() - 66 : 0;
    for (std::size_t i = b.size() - 1; i > from; --i)
      if (b[i - 1] == 0xff && b[i] == 0xd9) return;
    throw DatasetError(path, 0, "truncated JPEG (no end-of-image marker)");
  }
}

template <typename Decode>
auto decode(const fs::path& path, Decode&& how) {
  const std::vector<unsigned char> bytes = readBytes(path);
  checkComplete(path, bytes);
  try {
    return how(std::span<const std::uint8_t>(bytes.data(), bytes.size()), path.string());
  } catch (const io::ImageFileError& e) {
    // The message starts with the file; DatasetError adds it again.
    std::string what = e.what();
    if (const std::string prefix = path.string() + ": "; what.rfind(prefix, 0) == 0)
      what.erase(0, prefix.size());
    throw DatasetError(path, 0, what);
  }
}

template <typename Image>
void checkSize(const fs::path& path, const Image& m, const CameraIntrinsics& k) {
  if (m.width != k.width || m.height != k.height)
    throw DatasetError(path, 0,
                       "image is " + std::to_string(m.width) + "x" + std::to_string(m.height) +
                           ", the camera intrinsics are for " + std::to_string(k.width) + "x" +
                           std::to_string(k.height));
}

}  // namespace

RgbdImages loadRgbdImages(const RgbdSequence& sequence, std::size_t i) {
  if (i >= sequence.frames.size())
    throw std::out_of_range("loadRgbdImages: frame " + std::to_string(i) + " of " +
                            std::to_string(sequence.frames.size()));
  const RgbdFrameInfo& frame = sequence.frames[i];
  const CameraIntrinsics& k = sequence.intrinsics;

  RgbdImages out;
  out.width = k.width;
  out.height = k.height;
  out.depth_scale = sequence.depth_scale;

  io::Rgb8 rgb = decode(frame.color_path, io::decodeRgb8);
  checkSize(frame.color_path, rgb, k);
  out.color = std::move(rgb.pixels);

  io::Gray16 depth = decode(frame.depth_path, io::decodeGray16);
  checkSize(frame.depth_path, depth, k);
  out.depth = std::move(depth.pixels);
  if (sequence.layout == RgbdLayout::kSevenScenes) {
    for (auto& d : out.depth)
      if (d == 65535) d = 0;  // 7-Scenes marks invalid depth with 65535
  }
  return out;
}

std::vector<float> depthInMetres(const RgbdImages& images) {
  std::vector<float> out(images.depth.size());
  const double inv = 1.0 / images.depth_scale;
  for (std::size_t i = 0; i < out.size(); ++i)
    out[i] = images.depth[i] == 0 ? std::numeric_limits<float>::quiet_NaN()
                                  : static_cast<float>(images.depth[i] * inv);
  return out;
}

}  // namespace tessera::datasets
