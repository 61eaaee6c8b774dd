#include <tessera/geometry/pose2.hpp>
#include <tessera/io/atomic_file.hpp>
#include <tessera/line_slam/line_map_io.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <limits>
#include <numbers>
#include <sstream>
#include <stdexcept>

namespace tessera::line_slam {
namespace fs = std::filesystem;

std::vector<MapSegment> readWallSegments(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read '" + path.string() + "'");
  std::vector<MapSegment> out;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    const auto start = line.find_first_not_of(" \t\r");
    if (start == std::string::npos || line[start] == '#') continue;
    std::istringstream row(line);
    double v[4];
    std::string extra;
    if (!(row >> v[0] >> v[1] >> v[2] >> v[3]) || (row >> extra) ||
        !std::all_of(v, v + 4, [](double x) { return std::isfinite(x); }))
      throw std::runtime_error(path.string() + ":" + std::to_string(number) +
                               ": expected 'x0 y0 x1 y1' (4 finite numbers)");
    MapSegment s;
    s.id = static_cast<std::int64_t>(out.size());
    s.p0 = {v[0], v[1]};
    s.p1 = {v[2], v[3]};
    const Eigen::Vector2d d = s.p1 - s.p0;
    s.phi = std::atan2(d.x(), -d.y());  // normal = direction turned by −90°
    s.r = s.p0.dot(Eigen::Vector2d(std::cos(s.phi), std::sin(s.phi)));
    if (s.r < 0) {
      s.r = -s.r;
      s.phi = normalizeAngle(s.phi + std::numbers::pi);
    }
    out.push_back(s);
  }
  return out;
}

void writeLinesCsv(const fs::path& path, const std::vector<MapSegment>& lines) {
  io::AtomicFile file(path);  // throws io::FileWriteError naming the file and the reason
  std::ostream& out = file.stream();
  out << std::setprecision(10) << "id,r,phi,var_r,cov_r_phi,var_phi,x0,y0,x1,y1,observations\n";
  for (const auto& l : lines)
    out << l.id << ',' << l.r << ',' << l.phi << ',' << l.covariance(0, 0) << ','
        << l.covariance(0, 1) << ',' << l.covariance(1, 1) << ',' << l.p0.x() << ',' << l.p0.y()
        << ',' << l.p1.x() << ',' << l.p1.y() << ',' << l.observations << '\n';
  file.commit();
}

void writeLinesSvg(const fs::path& path, const std::vector<MapSegment>& lines,
                   const std::vector<MapSegment>& walls,
                   const std::vector<Eigen::Vector2d>& trajectory, double ppm) {
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector2d hi = -lo;
  const auto grow = [&](const Eigen::Vector2d& p) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  };
  for (const auto* set : {&lines, &walls})
    for (const auto& s : *set) {
      grow(s.p0);
      grow(s.p1);
    }
  for (const auto& p : trajectory) grow(p);
  if (!lo.allFinite()) lo = hi = Eigen::Vector2d::Zero();
  lo -= Eigen::Vector2d::Constant(0.5);
  hi += Eigen::Vector2d::Constant(0.5);
  const double w = (hi.x() - lo.x()) * ppm, h = (hi.y() - lo.y()) * ppm;
  // SVG y grows downwards: flip so the map's y axis points up.
  const auto px = [&](const Eigen::Vector2d& p) {
    std::ostringstream s;
    s << std::fixed << std::setprecision(1) << (p.x() - lo.x()) * ppm << ','
      << (hi.y() - p.y()) * ppm;
    return s.str();
  };
  io::AtomicFile file(path);  // throws io::FileWriteError naming the file and the reason
  std::ostream& out = file.stream();
  out << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << std::lround(w) << "\" height=\""
      << std::lround(h) << "\" viewBox=\"0 0 " << std::lround(w) << ' ' << std::lround(h)
      << "\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  const auto segment = [&](const MapSegment& s, const char* colour, double width) {
    const std::string a = px(s.p0), b = px(s.p1);
    out << "<line x1=\"" << a.substr(0, a.find(',')) << "\" y1=\"" << a.substr(a.find(',') + 1)
        << "\" x2=\"" << b.substr(0, b.find(',')) << "\" y2=\"" << b.substr(b.find(',') + 1)
        << "\" stroke=\"" << colour << "\" stroke-width=\"" << width << "\"/>\n";
  };
  for (const auto& s : walls) segment(s, "#bbbbbb", 6);
  if (!trajectory.empty()) {
    out << "<polyline fill=\"none\" stroke=\"#d62728\" stroke-width=\"1.5\" points=\"";
    for (const auto& p : trajectory) out << px(p) << ' ';
    out << "\"/>\n";
  }
  for (const auto& s : lines) segment(s, "#1f77b4", 2);
  out << "</svg>\n";
  file.commit();
}

namespace {

/// True when `a` lies along `b`: parallel within the angle, a's end points near b's infinite
/// line, and a covering at least `min_coverage` of b's length.
bool lies(const MapSegment& a, const MapSegment& b, const LineMapScoreOptions& o,
          bool coverage_of_b) {
  const Eigen::Vector2d db = b.p1 - b.p0, da = a.p1 - a.p0;
  const double lb = db.norm(), la = da.norm();
  if (lb <= 0 || la <= 0) return false;
  const Eigen::Vector2d u = db / lb, n(-u.y(), u.x());
  const double cosang = std::abs(u.dot(da / la));
  if (std::acos(std::min(1.0, cosang)) > o.max_angle) return false;
  // Distances of the overlapping part's ends: use the wall-side end points of the overlap.
  const double t0 = (a.p0 - b.p0).dot(u), t1 = (a.p1 - b.p0).dot(u);
  const double lo = std::max(0.0, std::min(t0, t1)), hi = std::min(lb, std::max(t0, t1));
  if (hi <= lo) return false;
  const auto offset = [&](double t) {  // a's perpendicular offset from b at b-coordinate t
    const double f = (t - t0) / (t1 - t0);
    return std::abs((a.p0 + f * (a.p1 - a.p0) - b.p0).dot(n));
  };
  if (std::abs(t1 - t0) > 1e-9 && (offset(lo) > o.max_distance || offset(hi) > o.max_distance))
    return false;
  return (hi - lo) >= o.min_coverage * (coverage_of_b ? lb : la);
}

}  // namespace

LineMapScore scoreLineMap(const std::vector<MapSegment>& lines,
                          const std::vector<MapSegment>& walls, const LineMapScoreOptions& o) {
  LineMapScore s;
  s.walls = static_cast<int>(walls.size());
  s.lines = static_cast<int>(lines.size());
  for (const auto& w : walls)
    if (std::any_of(lines.begin(), lines.end(),
                    [&](const MapSegment& l) { return lies(l, w, o, true); }))
      ++s.walls_matched;
  for (const auto& l : lines)
    if (std::any_of(walls.begin(), walls.end(),
                    [&](const MapSegment& w) { return lies(l, w, o, false); }))
      ++s.lines_on_walls;
  return s;
}

}  // namespace tessera::line_slam
