#include <tessera/datasets/landmark_logs.hpp>

#include <tessera/geometry/pose2.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <set>
#include <sstream>
#include <string>

namespace tessera::datasets {

using io::DatasetError;
using io::Fields;
using io::ParseReport;
using io::TextReader;
namespace {

// Unix times up to the year 2286: anything larger is a corrupt field, and bounding it keeps the
// player's nanosecond arithmetic far from overflow.
constexpr double kMaxTime = 1e10;
constexpr std::int64_t kMaxSubject = 1000;
constexpr std::int64_t kMaxBarcode = 1000000;
constexpr std::int64_t kMaxId = 2147483647;

std::string number(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

bool skippable(const Fields& f) {
  return f.empty() || f[0].front() == '#';
}

double checkedTime(const Fields& f, std::size_t i, double previous) {
  const double t = f.real(i, "time");
  if (t < 0 || t > kMaxTime)
    f.fail("field " + std::to_string(i + 1) + " (time): expected 0.." + number(kMaxTime) +
           " s, got " + number(t));
  if (t < previous)
    f.fail("time goes backwards: " + number(t) + " s after " + number(previous) + " s");
  return t;
}

double nonNegative(const Fields& f, std::size_t i, std::string_view label) {
  const double v = f.real(i, label);
  if (v < 0)
    f.fail("field " + std::to_string(i + 1) + " (" + std::string(label) + "): must be >= 0, got " +
           number(v));
  return v;
}

template <int N>
bool positiveSemidefinite(const Eigen::Matrix<double, N, N>& m) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N>> solver(m, Eigen::EigenvaluesOnly);
  if (solver.info() != Eigen::Success) return false;
  const auto& ev = solver.eigenvalues();
  const double scale = ev.cwiseAbs().maxCoeff();
  return std::isfinite(scale) && ev.minCoeff() >= -1e-9 * scale;
}

std::optional<std::filesystem::path> findFile(const std::filesystem::path& folder,
                                              const std::string& name) {
  for (const auto& candidate : {folder / name, folder / (name + ".gz")}) {
    std::error_code ec;
    if (std::filesystem::is_regular_file(candidate, ec)) return candidate;
  }
  return std::nullopt;
}

}  // namespace

// ---- MRCLAM ----

std::map<int, int> readMrclamBarcodes(TextReader& reader) {
  std::map<int, int> barcode_to_subject;
  std::set<int> subjects;
  std::string line;
  while (reader.next(line)) {
    const Fields f(reader, line);
    if (skippable(f)) continue;
    f.requireExactly(2, "barcode row (subject barcode)");
    const int subject = static_cast<int>(f.integerIn(0, "subject", 1, kMaxSubject));
    const int barcode = static_cast<int>(f.integerIn(1, "barcode", 0, kMaxBarcode));
    if (!subjects.insert(subject).second)
      f.fail("subject " + std::to_string(subject) + " is listed twice");
    if (!barcode_to_subject.emplace(barcode, subject).second)
      f.fail("barcode " + std::to_string(barcode) + " is listed twice");
  }
  if (barcode_to_subject.empty()) reader.fail("no barcodes in the file");
  return barcode_to_subject;
}

std::vector<MrclamLandmark> readMrclamLandmarks(TextReader& reader,
                                                const std::map<int, int>& barcode_to_subject) {
  std::map<int, int> subject_to_barcode;
  for (const auto& [barcode, subject] : barcode_to_subject) subject_to_barcode[subject] = barcode;
  std::vector<MrclamLandmark> landmarks;
  std::set<int> seen;
  std::string line;
  while (reader.next(line)) {
    const Fields f(reader, line);
    if (skippable(f)) continue;
    f.requireExactly(5, "landmark row (subject x y std_x std_y)");
    MrclamLandmark l;
    l.subject = static_cast<int>(f.integerIn(0, "subject", 1, kMaxSubject));
    if (l.subject <= kMrclamRobots)
      f.fail("subject " + std::to_string(l.subject) + " is a robot, not a landmark");
    const auto b = subject_to_barcode.find(l.subject);
    if (b == subject_to_barcode.end())
      f.fail("subject " + std::to_string(l.subject) + " has no barcode in Barcodes.dat");
    if (!seen.insert(l.subject).second)
      f.fail("subject " + std::to_string(l.subject) + " is listed twice");
    l.barcode = b->second;
    l.x = f.real(1, "x");
    l.y = f.real(2, "y");
    l.std_x = nonNegative(f, 3, "std_x");
    l.std_y = nonNegative(f, 4, "std_y");
    landmarks.push_back(l);
  }
  if (landmarks.empty()) reader.fail("no landmarks in the file");
  return landmarks;
}

std::vector<MrclamOdometry> readMrclamOdometry(TextReader& reader, ParseReport& report) {
  std::vector<MrclamOdometry> rows;
  std::string line;
  double previous = 0;
  while (reader.next(line)) {
    ++report.lines;
    const Fields f(reader, line);
    if (skippable(f)) continue;
    f.requireExactly(3, "odometry row (time v omega)");
    MrclamOdometry o;
    o.time = previous = checkedTime(f, 0, previous);
    o.v = f.real(1, "v");
    o.omega = f.real(2, "omega");
    rows.push_back(o);
    ++report.records;
  }
  return rows;
}

std::vector<MrclamMeasurement> readMrclamMeasurements(TextReader& reader,
                                                      const std::map<int, int>& barcode_to_subject,
                                                      const std::vector<MrclamLandmark>& landmarks,
                                                      ParseReport& report) {
  std::map<int, int> landmark_index;
  for (std::size_t i = 0; i < landmarks.size(); ++i)
    landmark_index[landmarks[i].subject] = static_cast<int>(i);
  std::vector<MrclamMeasurement> rows;
  std::string line;
  double previous = 0;
  while (reader.next(line)) {
    ++report.lines;
    const Fields f(reader, line);
    if (skippable(f)) continue;
    f.requireExactly(4, "measurement row (time barcode range bearing)");
    MrclamMeasurement m;
    m.time = previous = checkedTime(f, 0, previous);
    m.barcode = static_cast<int>(f.integerIn(1, "barcode", 0, kMaxBarcode));
    m.range = nonNegative(f, 2, "range");
    m.bearing = f.real(3, "bearing");
    const auto s = barcode_to_subject.find(m.barcode);
    if (s == barcode_to_subject.end()) {
      report.skip(reader, "unknown barcode");
      continue;
    }
    m.subject = s->second;
    m.is_robot = m.subject <= kMrclamRobots;
    if (!m.is_robot) {
      const auto l = landmark_index.find(m.subject);
      if (l == landmark_index.end()) {
        report.skip(reader, "landmark without ground truth");
        continue;
      }
      m.landmark_index = l->second;
    }
    rows.push_back(m);
    ++report.records;
  }
  return rows;
}

std::vector<MrclamPose> readMrclamGroundTruth(TextReader& reader, ParseReport& report) {
  std::vector<MrclamPose> rows;
  std::string line;
  double previous = 0;
  while (reader.next(line)) {
    ++report.lines;
    const Fields f(reader, line);
    if (skippable(f)) continue;
    f.requireExactly(4, "ground-truth row (time x y theta)");
    MrclamPose p;
    p.time = previous = checkedTime(f, 0, previous);
    p.x = f.real(1, "x");
    p.y = f.real(2, "y");
    p.theta = f.real(3, "theta");
    rows.push_back(p);
    ++report.records;
  }
  return rows;
}

MrclamRobotLog readMrclam(const std::filesystem::path& folder, int robot) {
  if (robot < 1 || robot > kMrclamRobots)
    throw DatasetError(folder, 0,
                       "MRCLAM robot must be 1.." + std::to_string(kMrclamRobots) + ", got " +
                           std::to_string(robot));
  MrclamRobotLog log;
  log.robot = robot;
  auto required = [&](const std::string& name) {
    auto p = findFile(folder, name);
    if (!p) throw DatasetError(folder / name, 0, "missing (also looked for " + name + ".gz)");
    return *p;
  };
  {
    TextReader r(required("Barcodes.dat"));
    log.barcode_to_subject = readMrclamBarcodes(r);
  }
  {
    TextReader r(required("Landmark_Groundtruth.dat"));
    log.landmarks = readMrclamLandmarks(r, log.barcode_to_subject);
  }
  const std::string prefix = "Robot" + std::to_string(robot) + "_";
  {
    TextReader r(required(prefix + "Odometry.dat"));
    log.odometry = readMrclamOdometry(r, log.report);
  }
  {
    TextReader r(required(prefix + "Measurement.dat"));
    log.measurements = readMrclamMeasurements(r, log.barcode_to_subject, log.landmarks, log.report);
  }
  if (auto gt = findFile(folder, prefix + "Groundtruth.dat")) {
    TextReader r(*gt);
    log.ground_truth = readMrclamGroundTruth(r, log.report);
  }
  return log;
}

// ---- Victoria Park ----

VictoriaParkLog readVictoriaPark(TextReader& reader) {
  VictoriaParkLog log;
  ParseReport& report = log.report;
  struct RawOdometry {
    VictoriaOdometry o;
    std::size_t line;
  };
  struct RawObservation {
    VictoriaObservation o;
    std::size_t line;
  };
  std::vector<RawOdometry> odometry;
  std::vector<RawObservation> observations;

  std::string line;
  while (reader.next(line)) {
    ++report.lines;
    const Fields f(reader, line);
    if (skippable(f)) continue;
    if (f[0] == "ODOMETRY") {
      f.requireExactly(12, "ODOMETRY");
      VictoriaOdometry o;
      o.from_id = f.integerIn(1, "from id", 0, kMaxId);
      o.to_id = f.integerIn(2, "to id", 0, kMaxId);
      o.delta = {f.real(3, "dx"), f.real(4, "dy"), f.real(5, "dtheta")};
      double c[6];
      for (int i = 0; i < 6; ++i) c[i] = f.real(6 + static_cast<std::size_t>(i), "covariance");
      o.covariance << c[0], c[1], c[2], c[1], c[3], c[4], c[2], c[4], c[5];
      if (!positiveSemidefinite<3>(o.covariance))
        f.fail("odometry covariance is not positive semidefinite");
      odometry.push_back({o, reader.lineNumber()});
    } else if (f[0] == "LANDMARK") {
      f.requireExactly(8, "LANDMARK");
      VictoriaObservation o;
      o.pose_id = f.integerIn(1, "pose id", 0, kMaxId);
      o.landmark_id = f.integerIn(2, "landmark id", 0, kMaxId);
      o.position = {f.real(3, "x"), f.real(4, "y")};
      const double vxx = f.real(5, "var x"), vxy = f.real(6, "cov xy"), vyy = f.real(7, "var y");
      o.covariance << vxx, vxy, vxy, vyy;
      if (!positiveSemidefinite<2>(o.covariance))
        f.fail("landmark covariance is not positive semidefinite");
      o.range = std::hypot(o.position.x(), o.position.y());
      o.bearing = normalizeAngle(std::atan2(o.position.y(), o.position.x()));
      const double largest_eigenvalue = 0.5 * (vxx + vyy) + std::hypot(0.5 * (vxx - vyy), vxy);
      const double var = std::abs(vxx - vyy) < 1e-4 ? vxx : largest_eigenvalue;
      o.range_std = std::sqrt(var);
      o.bearing_std = std::sqrt(var / 10.0);
      if (!std::isfinite(o.range)) f.fail("landmark position is too far to give a range");
      observations.push_back({o, reader.lineNumber()});
    } else {
      report.skip(reader, "unknown tag");
    }
  }
  if (odometry.empty() && observations.empty())
    reader.fail("no ODOMETRY or LANDMARK line: not a GTSAM landmark file");

  // Dense indices, in increasing id order, in the shared id space.
  std::set<std::int64_t> pose_ids, landmark_ids;
  for (const auto& r : odometry) {
    pose_ids.insert(r.o.from_id);
    pose_ids.insert(r.o.to_id);
  }
  for (const auto& r : observations) {
    pose_ids.insert(r.o.pose_id);
    landmark_ids.insert(r.o.landmark_id);
  }
  for (const auto& r : observations) {
    if (landmark_ids.count(r.o.pose_id) || pose_ids.count(r.o.landmark_id)) {
      const std::int64_t id = landmark_ids.count(r.o.pose_id) ? r.o.pose_id : r.o.landmark_id;
      throw DatasetError(reader.path(), r.line,
                         "id " + std::to_string(id) + " is used both as a pose and a landmark");
    }
  }
  std::map<std::int64_t, std::size_t> pose_index, landmark_index;
  for (const auto id : pose_ids) {
    pose_index.emplace(id, log.pose_ids.size());
    log.pose_ids.push_back(id);
  }
  for (const auto id : landmark_ids) {
    landmark_index.emplace(id, log.landmark_ids.size());
    log.landmark_ids.push_back(id);
  }

  // Odometry must be the chain 0 -> 1 -> 2 ... in file order.
  for (std::size_t k = 0; k < odometry.size(); ++k) {
    auto& r = odometry[k];
    const std::size_t from = pose_index.at(r.o.from_id), to = pose_index.at(r.o.to_id);
    if (from != k || to != k + 1)
      throw DatasetError(reader.path(), r.line,
                         "odometry is not a chain: ODOMETRY " + std::to_string(r.o.from_id) + " " +
                             std::to_string(r.o.to_id) + " is odometry line " +
                             std::to_string(k + 1) + " but goes from pose index " +
                             std::to_string(from) + " to " + std::to_string(to) + " (expected " +
                             std::to_string(k) + " to " + std::to_string(k + 1) + ")");
    r.o.from_index = from;
    log.odometry.push_back(r.o);
  }
  const std::size_t chain_poses = odometry.size() + 1;
  for (auto& r : observations) {
    r.o.pose_index = pose_index.at(r.o.pose_id);
    r.o.landmark_index = landmark_index.at(r.o.landmark_id);
    if (r.o.pose_index >= chain_poses)
      throw DatasetError(reader.path(), r.line,
                         "pose " + std::to_string(r.o.pose_id) + " is not on the odometry chain");
    if (r.o.range == 0) {
      report.skip(reader.path(), r.line, "landmark at zero range");
      continue;
    }
    log.observations.push_back(r.o);
  }
  report.records = log.odometry.size() + log.observations.size();
  return log;
}

VictoriaParkLog readVictoriaPark(const std::filesystem::path& path) {
  TextReader reader(path);
  return readVictoriaPark(reader);
}

}  // namespace tessera::datasets
