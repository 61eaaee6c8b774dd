// Tests for the AIEPF line extractor (weighted TLS fits, fuzzy c-lines splits, merges).
#include <tessera/line_slam/line_extraction.hpp>
#include <tessera/line_slam/line_map_io.hpp>

#include <Eigen/LU>
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

using namespace tessera::line_slam;
using namespace tessera;
using namespace tessera::grid;

namespace {

/// n points from a to b with Gaussian noise of `sigma` in both coordinates.
std::vector<Eigen::Vector2d> noisyLine(const Eigen::Vector2d& a, const Eigen::Vector2d& b, int n,
                                       double sigma, std::mt19937_64& rng) {
  std::normal_distribution<double> noise(0.0, sigma);
  std::vector<Eigen::Vector2d> out;
  for (int i = 0; i < n; ++i) {
    const double t = static_cast<double>(i) / (n - 1);
    out.push_back(a + t * (b - a) + Eigen::Vector2d(noise(rng), noise(rng)));
  }
  return out;
}

/// A scan of the inside of an axis-aligned box seen from `origin` (laser at the origin, heading
/// +x), beams over `fov` rad, exact ranges plus noise.
std::vector<float> boxScan(double xmin, double xmax, double ymin, double ymax, int beams,
                           double fov, double sigma, std::mt19937_64& rng) {
  std::normal_distribution<double> noise(0.0, sigma);
  std::vector<float> ranges;
  for (int k = 0; k < beams; ++k) {
    const double a = -fov / 2 + fov * k / (beams - 1);
    const double c = std::cos(a), s = std::sin(a);
    double t = std::numeric_limits<double>::infinity();
    if (c > 1e-9) t = std::min(t, xmax / c);
    if (c < -1e-9) t = std::min(t, xmin / c);
    if (s > 1e-9) t = std::min(t, ymax / s);
    if (s < -1e-9) t = std::min(t, ymin / s);
    ranges.push_back(static_cast<float>(t + noise(rng)));
  }
  return ranges;
}

}  // namespace

TEST_CASE("weighted total least squares recovers a known line and a consistent covariance",
          "[lines][line_extraction]") {
  std::mt19937_64 rng(3);
  const double r_true = 2.0, phi_true = 0.7;
  const Eigen::Vector2d n(std::cos(phi_true), std::sin(phi_true)), d(-n.y(), n.x());
  double nees = 0;
  const int trials = 300;
  for (int k = 0; k < trials; ++k) {
    // Noise only across the line, so the covariance model (isotropic, 1 cm) is exact in r, φ.
    std::normal_distribution<double> noise(0.0, 0.01);
    std::vector<Eigen::Vector2d> pts;
    for (int i = 0; i < 80; ++i) pts.push_back(r_true * n + (-1.0 + 0.04 * i) * d + noise(rng) * n);
    const LineFit f = fitLineWtls(pts, {}, 0.01);
    REQUIRE(f.valid);
    const Eigen::Vector2d e(f.r - r_true, angleDiff(f.phi, phi_true));
    CHECK(std::abs(e(0)) < 0.01);
    CHECK(std::abs(e(1)) < 0.02);
    nees += e.dot(f.covariance.inverse() * e);
  }
  // The mean normalised error squared of a 2-dof estimate with a right covariance is 2.
  nees /= trials;
  CHECK(nees > 1.6);
  CHECK(nees < 2.5);
}

TEST_CASE("line fits normalise r to be non-negative and honour weights",
          "[lines][line_extraction]") {
  // The line y = -1 seen from the origin: normal points to -y.
  std::vector<Eigen::Vector2d> pts{{-1, -1}, {0, -1}, {1, -1}, {5, 3}};
  std::vector<double> w{1, 1, 1, 0};  // the outlier has no weight
  const LineFit f = fitLineWtls(pts, w, 0.01);
  REQUIRE(f.valid);
  CHECK(f.r == Approx(1.0).margin(1e-9));
  CHECK(f.phi == Approx(-std::numbers::pi / 2).margin(1e-9));
  // Two coincident points define no line.
  std::vector<Eigen::Vector2d> same{{1, 1}, {1, 1}};
  CHECK_FALSE(fitLineWtls(same, {}, 0.01).valid);
}

TEST_CASE("fuzzy split separates an L-shaped corner", "[lines][line_extraction]") {
  std::mt19937_64 rng(5);
  auto pts = noisyLine({0, 1}, {2, 1}, 60, 0.005, rng);
  const auto leg = noisyLine({2, 1}, {2, 3}, 60, 0.005, rng);
  pts.insert(pts.end(), leg.begin() + 1, leg.end());  // the corner point once
  const LineExtractor ex;
  const int k = ex.fuzzySplit(pts, {}, 0, static_cast<int>(pts.size()));
  CHECK(std::abs(k - 60) <= 2);

  LineExtractionStats stats;
  const auto segs = ex.extract(pts, {}, &stats);
  REQUIRE(segs.size() == 2);
  CHECK(stats.splits >= 1);
  CHECK(segs[0].line.r == Approx(1.0).margin(0.01));
  CHECK(segs[0].line.phi == Approx(std::numbers::pi / 2).margin(0.01));
  CHECK(segs[1].line.r == Approx(2.0).margin(0.01));
  CHECK(segs[1].line.phi == Approx(0.0).margin(0.01));
  CHECK((segs[0].p1 - Eigen::Vector2d(2, 1)).norm() < 0.06);
  CHECK((segs[1].p0 - Eigen::Vector2d(2, 1)).norm() < 0.06);
}

TEST_CASE("a straight noisy wall stays one segment", "[lines][line_extraction]") {
  std::mt19937_64 rng(9);
  const auto pts = noisyLine({-3, 2}, {3, 2.2}, 300, 0.01, rng);
  const auto segs = LineExtractor().extract(pts);
  REQUIRE(segs.size() == 1);
  CHECK(segs[0].points() == 300);
  CHECK(segs[0].length() == Approx(std::hypot(6.0, 0.2)).margin(0.05));
}

TEST_CASE("extractor finds the walls of a box in a scan and breaks at gaps",
          "[lines][line_extraction]") {
  std::mt19937_64 rng(11);
  const int beams = 361;
  const double fov = std::numbers::pi;
  // The box from -2..4 in x and -1.5..2.5 in y: three walls visible over 180°.
  std::vector<float> ranges = boxScan(-2, 4, -1.5, 2.5, beams, fov, 0.01, rng);
  // Invalid and missing beams: NaN, +inf, too close.
  ranges[10] = std::numeric_limits<float>::quiet_NaN();
  ranges[200] = std::numeric_limits<float>::infinity();
  ranges[300] = 0.001f;
  const RangeScan scan{ranges, -fov / 2, fov / (beams - 1), 0.02, 30.0};
  LineExtractionStats stats;
  const auto segs = LineExtractor().extract(scan, &stats);
  CHECK(stats.invalid_beams == 2);
  CHECK(stats.no_return == 1);
  REQUIRE(segs.size() == 3);
  // y = -1.5 (right), x = 4 (ahead), y = 2.5 (left), in scan order.
  CHECK(segs[0].line.r == Approx(1.5).margin(0.01));
  CHECK(segs[0].line.phi == Approx(-std::numbers::pi / 2).margin(0.01));
  CHECK(segs[1].line.r == Approx(4.0).margin(0.01));
  CHECK(segs[1].line.phi == Approx(0.0).margin(0.01));
  CHECK(segs[2].line.r == Approx(2.5).margin(0.01));
  CHECK(segs[2].line.phi == Approx(std::numbers::pi / 2).margin(0.01));

  // A scan of nothing usable gives nothing, without failing.
  std::vector<float> bad(50, std::numeric_limits<float>::quiet_NaN());
  CHECK(LineExtractor().extract(RangeScan{bad, 0, 0.01, 0.02, 30.0}, &stats).empty());
  CHECK(stats.invalid_beams == 50);
  CHECK(LineExtractor().extract(RangeScan{{}, 0, 0.01, 0.02, 30.0}).empty());
}

TEST_CASE("transformSegment moves lines between frames and back", "[lines][line_extraction]") {
  LineSegment s;
  s.line.r = 1.5;
  s.line.phi = 0.3;
  s.line.covariance << 1e-4, 2e-5, 2e-5, 1e-4;
  s.p0 = s.line.r * s.line.normal() - s.line.direction();
  s.p1 = s.line.r * s.line.normal() + s.line.direction();
  const Pose2 pose(2.0, -1.0, 2.5);
  const LineSegment w = transformSegment(s, pose);
  // The end points still lie on the transformed line.
  CHECK(w.line.distance(w.p0) == Approx(0.0).margin(1e-9));
  CHECK(w.line.distance(w.p1) == Approx(0.0).margin(1e-9));
  CHECK(w.line.r >= 0);
  const LineSegment back = transformSegment(w, pose.inverse());
  CHECK(back.line.r == Approx(s.line.r).margin(1e-9));
  CHECK(angleDiff(back.line.phi, s.line.phi) == Approx(0.0).margin(1e-9));
  CHECK((back.line.covariance - s.line.covariance).norm() < 1e-12);
}

TEST_CASE("extractor options are checked", "[lines][line_extraction]") {
  LineExtractorOptions o;
  o.min_points = 1;
  CHECK_THROWS_AS(LineExtractor(o), std::invalid_argument);
  o = {};
  o.fuzzy_exponent = 1.0;
  CHECK_THROWS_AS(LineExtractor(o), std::invalid_argument);
}

TEST_CASE("line maps are scored against true walls and written as CSV and SVG",
          "[lines][line_map_io]") {
  const auto dir = std::filesystem::temp_directory_path() / "tessera_line_map_io";
  std::filesystem::create_directories(dir);
  {
    std::ofstream walls(dir / "walls.txt");
    walls << "# 2 walls\n0 0 4 0\n4 0 4 3\n";
  }
  const auto walls = readWallSegments(dir / "walls.txt");
  REQUIRE(walls.size() == 2);
  CHECK(walls[0].r == Approx(0.0).margin(1e-12));
  CHECK(walls[1].r == Approx(4.0));
  std::vector<MapSegment> lines(3);
  lines[0].p0 = {0.1, 0.02};  // along the first wall
  lines[0].p1 = {3.9, 0.03};
  lines[1].p0 = {4.02, 0.5};  // covers only a third of the second wall
  lines[1].p1 = {4.02, 1.5};
  lines[2].p0 = {2, 2};  // spurious
  lines[2].p1 = {3, 2};
  const LineMapScore score = scoreLineMap(lines, walls);
  CHECK(score.walls == 2);
  CHECK(score.walls_matched == 1);
  CHECK(score.lines == 3);
  CHECK(score.lines_on_walls == 2);
  writeLinesCsv(dir / "lines.csv", lines);
  writeLinesSvg(dir / "lines.svg", lines, walls, {{0.5, 0.5}, {1, 1}});
  std::ifstream csv(dir / "lines.csv");
  int rows = 0;
  for (std::string line; std::getline(csv, line);) ++rows;
  CHECK(rows == 4);
  CHECK(std::filesystem::file_size(dir / "lines.svg") > 200);
  {
    std::ofstream bad(dir / "bad.txt");
    bad << "0 0 1\n";
  }
  CHECK_THROWS_AS(readWallSegments(dir / "bad.txt"), std::runtime_error);
}
