#include <tessera/scan_matching/correlative_matcher.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <span>
#include <stdexcept>
#include <string>

namespace tessera::scan_matching {
namespace {

// Deeper levels pad every level by 2^depth − 1 cells per axis; beyond 2^10 (51 m blocks at 5 cm)
// the padding costs far more memory than any window could use.
constexpr int kMaxDepth = 10;

void require(bool ok, const char* what) {
  if (!ok) throw std::invalid_argument(std::string("CorrelativeMatcher: ") + what);
}

// A probability as a stored cell value: rounded to the nearest 1/kScale (NaN is the caller's).
static_assert(MatchGrid::kScale <= std::numeric_limits<std::uint8_t>::max(),
              "MatchGrid cells are bytes");
std::uint8_t matchGridFixed(double p) {
  return static_cast<std::uint8_t>(std::lround(std::clamp(p, 0.0, 1.0) * MatchGrid::kScale));
}

/// One candidate or block: heading index, cell offset of its lower-left leaf, summed score.
struct Node {
  int angle;
  int x, y;
  std::int64_t sum;
};

/// A prepared search: the scan discretised at every heading, and the leaf lattice.
class Search {
 public:
  Search(const MatchGrid& grid, std::span<const Eigen::Vector2d> points, const Pose2& local,
         double step, int n_angles, int window_cells)
      : grid_(grid),
        points_(points.size()),
        step_(step),
        n_angles_(n_angles),
        w_(window_cells),
        local_(local) {
    const double inv_res = 1.0 / grid.resolution();
    cells_.reserve(points_ * static_cast<std::size_t>(2 * n_angles + 1));
    for (int j = -n_angles; j <= n_angles; ++j) {
      const double th = local.theta + j * step;
      const double c = std::cos(th), s = std::sin(th);
      for (const Eigen::Vector2d& p : points)
        cells_.emplace_back(
            static_cast<int>(std::floor((local.x + c * p.x() - s * p.y()) * inv_res)),
            static_cast<int>(std::floor((local.y + s * p.x() + c * p.y()) * inv_res)));
    }
  }

  int angles() const { return 2 * n_angles_ + 1; }
  int window() const { return w_; }

  /// Sum over the scan at heading index a (0-based) of level `level` at cell offset (x, y).
  /// Each term is at most kScale (200), so the int64 sum is exact for any scan size. With
  /// `need`, it stops early with some value below `need` once the points left cannot lift the
  /// partial sum to it: a block the search would prune anyway is not summed to the end, and a
  /// kept block has its exact sum, so the result is the same (~7 % of the loop detector's
  /// matching time on the Intel log).
  std::int64_t sum(int level, int a, int x, int y,
                   std::int64_t need = std::numeric_limits<std::int64_t>::min()) {
    ++scored_;
    std::int64_t s = 0;
    const Eigen::Vector2i* c = cells_.data() + static_cast<std::size_t>(a) * points_;
    constexpr std::size_t kChunk = 16;
    for (std::size_t i = 0; i < points_;) {
      const std::size_t end = std::min(points_, i + kChunk);
      for (; i < end; ++i) s += grid_.at(level, c[i].x() + x, c[i].y() + y);
      if (s + static_cast<std::int64_t>(points_ - i) * MatchGrid::kScale < need) return s;
    }
    return s;
  }

  /// Local pose of a leaf.
  Pose2 pose(const Node& n) const {
    const double res = grid_.resolution();
    return {local_.x + n.x * res, local_.y + n.y * res,
            local_.theta + (n.angle - n_angles_) * step_};
  }

  std::int64_t scored() const { return scored_; }

 private:
  const MatchGrid& grid_;
  std::size_t points_;
  double step_;
  int n_angles_;
  int w_;
  Pose2 local_;
  std::vector<Eigen::Vector2i> cells_;  // heading-major, then point
  std::int64_t scored_ = 0;
};

/// Leaves near the best one, which the second-best search skips.
struct Exclusion {
  Node best;
  double radius_cells2;  // squared exclusion radius [cells²]
  int angle_steps;       // headings within the exclusion angle on each side

  bool sameHeading(int a) const { return std::abs(a - best.angle) <= angle_steps; }
  bool near(int x, int y) const {
    const double dx = x - best.x, dy = y - best.y;
    return dx * dx + dy * dy <= radius_cells2;
  }
  bool leaf(const Node& n) const { return sameHeading(n.angle) && near(n.x, n.y); }
  /// Every leaf of the size×size block at (x, y) is excluded (the disc is convex, so its corners
  /// decide).
  bool block(int a, int x, int y, int size) const {
    const int e = size - 1;
    return sameHeading(a) && near(x, y) && near(x + e, y) && near(x, y + e) && near(x + e, y + e);
  }
};

/// Depth-first branch and bound. `floor` is the least sum worth finding; best.sum < 0 = none yet.
void descend(Search& search, std::span<Node> nodes, int level, std::int64_t floor, Node& best,
             const Exclusion* exclusion) {
  std::sort(nodes.begin(), nodes.end(), [](const Node& a, const Node& b) { return a.sum > b.sum; });
  auto need = [&] { return std::max(floor, best.sum + 1); };
  for (const Node& n : nodes) {
    if (n.sum < need()) break;  // sorted: nothing after can do better
    if (level == 0) {
      if (exclusion && exclusion->leaf(n)) continue;
      best = n;
      continue;
    }
    const int half = 1 << (level - 1);
    std::array<Node, 4> children;  // on the stack: this runs for every expanded block
    std::size_t count = 0;
    for (int b = 0; b < 2; ++b)
      for (int a = 0; a < 2; ++a) {
        const int cx = n.x + a * half, cy = n.y + b * half;
        if (cx > search.window() || cy > search.window()) continue;
        if (exclusion && exclusion->block(n.angle, cx, cy, half)) continue;
        const std::int64_t s = search.sum(level - 1, n.angle, cx, cy, need());
        if (s >= need()) children[count++] = {n.angle, cx, cy, s};
      }
    descend(search, std::span<Node>(children.data(), count), level - 1, floor, best, exclusion);
  }
}

Node branchAndBound(Search& search, int top, std::int64_t floor, const Exclusion* exclusion) {
  const int size = 1 << top;
  std::vector<Node> nodes;
  for (int a = 0; a < search.angles(); ++a)
    for (int y = -search.window(); y <= search.window(); y += size)
      for (int x = -search.window(); x <= search.window(); x += size) {
        if (exclusion && exclusion->block(a, x, y, size)) continue;
        nodes.push_back({a, x, y, search.sum(top, a, x, y)});
      }
  Node best{0, 0, 0, -1};
  descend(search, nodes, top, floor, best, exclusion);
  return best;
}

Node exhaustive(Search& search, std::int64_t floor, const Exclusion* exclusion) {
  Node best{0, 0, 0, -1};
  for (int a = 0; a < search.angles(); ++a)
    for (int y = -search.window(); y <= search.window(); ++y)
      for (int x = -search.window(); x <= search.window(); ++x) {
        const Node n{a, x, y, search.sum(0, a, x, y)};
        if (n.sum < std::max(floor, best.sum + 1)) continue;
        if (exclusion && exclusion->leaf(n)) continue;
        best = n;
      }
  return best;
}

/// The usable points: finite and within max_range of the robot.
std::vector<Eigen::Vector2d> usablePoints(std::span<const Eigen::Vector2d> points, double max_range,
                                          int* dropped, double* farthest) {
  std::vector<Eigen::Vector2d> out;
  out.reserve(points.size());
  double far = 0.0;
  for (const Eigen::Vector2d& p : points) {
    const double r = p.norm();
    if (!std::isfinite(r) || r > max_range) continue;
    far = std::max(far, r);
    out.push_back(p);
  }
  if (dropped) *dropped = static_cast<int>(points.size() - out.size());
  if (farthest) *farthest = far;
  return out;
}

/// Mean level-0 value of the points at a local pose, in [0, 1].
double meanProbability(const MatchGrid& grid, std::span<const Eigen::Vector2d> points,
                       const Pose2& local) {
  if (points.empty()) return 0.0;
  const double inv_res = 1.0 / grid.resolution();
  const double c = std::cos(local.theta), s = std::sin(local.theta);
  std::int64_t sum = 0;
  for (const Eigen::Vector2d& p : points)
    sum += grid.at(0, static_cast<int>(std::floor((local.x + c * p.x() - s * p.y()) * inv_res)),
                   static_cast<int>(std::floor((local.y + s * p.x() + c * p.y()) * inv_res)));
  return static_cast<double>(sum) / (static_cast<double>(points.size()) * MatchGrid::kScale);
}

}  // namespace

std::string MatchGrid::check(const GridView& view) {
  const std::size_t n = static_cast<std::size_t>(std::max(view.width, 0)) *
                        static_cast<std::size_t>(std::max(view.height, 0));
  if (view.width <= 0 || view.height <= 0)
    return "grid has no cells (" + std::to_string(view.width) + "x" + std::to_string(view.height) +
           ")";
  if (!(view.resolution > 0.0) || !std::isfinite(view.resolution))
    return "grid resolution must be positive and finite";
  if (!view.origin.isFinite()) return "grid origin is not finite";
  const bool has_percent = !view.percent.empty(), has_prob = !view.probability.empty();
  if (has_percent == has_prob)
    return "grid view must hold exactly one of percent or probability cells";
  if ((has_percent ? view.percent.size() : view.probability.size()) != n)
    return "grid cell count does not match width x height";
  return {};
}

std::size_t MatchGrid::bytes() const {
  std::size_t total = sizeof(MatchGrid) + levels_.capacity() * sizeof(Level);
  for (const Level& l : levels_) total += l.cells.capacity() * sizeof(std::uint8_t);
  return total;
}

MatchGrid::MatchGrid(const GridView& view, int depth, double unknown_probability) {
  require(depth >= 0 && depth <= kMaxDepth, "pyramid_depth must be in 0..10");
  require(unknown_probability >= 0.0 && unknown_probability <= 1.0,
          "unknown_probability must be in [0, 1]");
  unknown_ = matchGridFixed(unknown_probability);
  error_ = check(view);
  if (!error_.empty()) return;
  const std::size_t n =
      static_cast<std::size_t>(view.width) * static_cast<std::size_t>(view.height);
  const bool has_percent = !view.percent.empty();
  width_ = view.width;
  height_ = view.height;
  resolution_ = view.resolution;
  origin_ = view.origin;

  // Levels beyond the grid's size add only padding.
  int useful = 0;
  while (useful < depth && (1 << useful) < std::max(width_, height_)) ++useful;
  levels_.reserve(static_cast<std::size_t>(useful) + 1);

  Level base;
  base.width = static_cast<unsigned>(width_);
  base.height = static_cast<unsigned>(height_);
  base.cells.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (has_percent) {
      // p % is exactly 2p in units of 1/200; above 100 (not a ROS value) reads as 100.
      static_assert(MatchGrid::kScale == 200, "percent cells map exactly to 2p");
      const int v = view.percent[i];
      base.cells[i] = v < 0 ? unknown_ : static_cast<std::uint8_t>(2 * std::min(v, 100));
    } else {
      const float p = view.probability[i];
      base.cells[i] = std::isnan(p) ? unknown_ : matchGridFixed(p);
    }
  }
  levels_.push_back(std::move(base));

  for (int h = 1; h <= useful; ++h) {
    const int s = 1 << (h - 1);
    Level l;
    l.offset = (1 << h) - 1;
    l.width = static_cast<unsigned>(width_ + l.offset);
    l.height = static_cast<unsigned>(height_ + l.offset);
    l.cells.resize(static_cast<std::size_t>(l.width) * l.height);
    // Doubling: a 2^h block is four 2^(h−1) blocks, so each level costs four reads per cell.
    for (unsigned v = 0; v < l.height; ++v) {
      const int y = static_cast<int>(v) - l.offset;
      for (unsigned u = 0; u < l.width; ++u) {
        const int x = static_cast<int>(u) - l.offset;
        l.cells[static_cast<std::size_t>(v) * l.width + u] = std::max(
            {at(h - 1, x, y), at(h - 1, x + s, y), at(h - 1, x, y + s), at(h - 1, x + s, y + s)});
      }
    }
    levels_.push_back(std::move(l));
  }
}

const char* toString(MatchStatus s) {
  switch (s) {
    case MatchStatus::kMatched:
      return "matched";
    case MatchStatus::kBelowMinScore:
      return "below_min_score";
    case MatchStatus::kEmptyScan:
      return "empty_scan";
    case MatchStatus::kEmptyGrid:
      return "empty_grid";
    case MatchStatus::kBadWindow:
      return "bad_window";
    case MatchStatus::kBadPose:
      return "bad_pose";
  }
  return "unknown";
}

CorrelativeMatcher::CorrelativeMatcher(Options o) : options_(o) {
  require(o.pyramid_depth >= 0 && o.pyramid_depth <= kMaxDepth, "pyramid_depth must be in 0..10");
  require(std::isfinite(o.angular_step) && o.angular_step >= 0.0, "angular_step must be >= 0");
  require(o.max_angular_steps >= 1, "max_angular_steps must be >= 1");
  require(std::isfinite(o.max_range) && o.max_range > 0.0, "max_range must be > 0");
  require(o.min_score >= 0.0 && o.min_score <= 1.0, "min_score must be in [0, 1]");
  require(o.unknown_probability >= 0.0 && o.unknown_probability <= 1.0,
          "unknown_probability must be in [0, 1]");
  require(std::isfinite(o.exclusion_radius) && o.exclusion_radius >= 0.0,
          "exclusion_radius must be >= 0");
  require(std::isfinite(o.exclusion_angle) && o.exclusion_angle >= 0.0,
          "exclusion_angle must be >= 0");
  require(o.second_best_min_ratio >= 0.0 && o.second_best_min_ratio <= 1.0,
          "second_best_min_ratio must be in [0, 1]");
  require(std::isfinite(o.covariance_radius) && o.covariance_radius >= 0.0,
          "covariance_radius must be >= 0");
  require(o.covariance_angle_steps >= 0, "covariance_angle_steps must be >= 0");
  require(std::isfinite(o.covariance_temperature) && o.covariance_temperature > 0.0,
          "covariance_temperature must be > 0");
}

MatchGrid CorrelativeMatcher::precompute(const GridView& view) const {
  return MatchGrid(view, options_.pyramid_depth, options_.unknown_probability);
}

double CorrelativeMatcher::score(const MatchGrid& grid, std::span<const Eigen::Vector2d> points,
                                 const Pose2& pose) const {
  if (grid.empty() || !pose.isFinite()) return 0.0;
  const auto usable = usablePoints(points, options_.max_range, nullptr, nullptr);
  return meanProbability(grid, usable, grid.origin().inverse() * pose);
}

CorrelativeMatchResult CorrelativeMatcher::match(const MatchGrid& grid,
                                                 std::span<const Eigen::Vector2d> points,
                                                 const Pose2& initial,
                                                 const SearchWindow& window) const {
  Result r;
  r.pose = initial;
  double farthest = 0.0;
  const auto usable = usablePoints(points, options_.max_range, &r.points_dropped, &farthest);
  r.points_used = static_cast<int>(usable.size());
  if (grid.empty()) {
    r.status = MatchStatus::kEmptyGrid;
    return r;
  }
  if (!initial.isFinite()) {
    r.status = MatchStatus::kBadPose;
    return r;
  }
  if (!(std::isfinite(window.linear) && window.linear > 0.0 && std::isfinite(window.angular) &&
        window.angular >= 0.0)) {
    r.status = MatchStatus::kBadWindow;
    return r;
  }
  if (usable.empty()) {
    r.status = MatchStatus::kEmptyScan;
    return r;
  }

  const double res = grid.resolution();
  double step = options_.angular_step;
  if (step <= 0.0) {
    // Turning by step moves a point at range d by at most one cell (Hess et al. eq. 7); points
    // closer than half a cell would allow any turn, so d is floored there.
    const double d = std::max(farthest, res);
    step = std::acos(1.0 - res * res / (2.0 * d * d));
  }
  int n_angles = 0;
  if (window.angular > 0.0) {
    const double need = std::ceil(window.angular / step);
    if (need > options_.max_angular_steps) {
      n_angles = options_.max_angular_steps;
      step = window.angular / n_angles;
    } else {
      n_angles = static_cast<int>(need);
    }
  }
  r.angular_step = step;
  // Cells per side; capped so a wild window cannot overflow the int lattice.
  const int w = static_cast<int>(std::min(std::ceil(window.linear / res), 1.0e6));

  const Pose2 local = grid.origin().inverse() * initial;
  Search search(grid, usable, local, step, n_angles, w);
  int top = 0;
  while (top < grid.depth() && (1 << top) < 2 * w + 1) ++top;
  const double total = static_cast<double>(usable.size()) * MatchGrid::kScale;
  const auto floorOf = [&](double score) {
    return static_cast<std::int64_t>(std::ceil(score * total - 1e-6));
  };
  const bool bnb = options_.search == Options::Search::kBranchAndBound;

  const Node best = bnb ? branchAndBound(search, top, floorOf(options_.min_score), nullptr)
                        : exhaustive(search, floorOf(options_.min_score), nullptr);
  if (best.sum < 0) {
    r.status = MatchStatus::kBelowMinScore;
    r.nodes_scored = search.scored();
    return r;
  }
  r.status = MatchStatus::kMatched;
  const Pose2 best_local = search.pose(best);
  r.pose = grid.origin() * best_local;
  r.score = static_cast<double>(best.sum) / total;

  if (options_.compute_second_best) {
    // The relative tolerance keeps lattice points exactly on the circle inside it despite
    // rounding in radius / res.
    const Exclusion exclusion{best, std::pow(options_.exclusion_radius / res, 2) * (1.0 + 1e-9),
                              static_cast<int>(std::floor(options_.exclusion_angle / step))};
    const std::int64_t floor2 =
        std::max(floorOf(options_.min_score),
                 floorOf(options_.second_best_min_ratio * static_cast<double>(best.sum) / total));
    const Node second = bnb ? branchAndBound(search, top, floor2, &exclusion)
                            : exhaustive(search, floor2, &exclusion);
    if (second.sum >= 0) {
      r.second_best_score = static_cast<double>(second.sum) / total;
      r.second_best_pose = grid.origin() * search.pose(second);
    }
  }
  r.nodes_scored = search.scored();

  // Covariance on the leaf lattice around the best (see the header comment).
  const int c = static_cast<int>(std::ceil(options_.covariance_radius / res));
  const int ca = options_.covariance_angle_steps;
  Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
  double wsum = 0.0;
  for (int dj = -ca; dj <= ca; ++dj) {
    const Pose2 turned(best_local.x, best_local.y, best_local.theta + dj * step);
    Search ring(grid, usable, turned, step, 0, c);
    for (int dy = -c; dy <= c; ++dy)
      for (int dx = -c; dx <= c; ++dx) {
        const double s = static_cast<double>(ring.sum(0, 0, dx, dy)) / total;
        const double wt = std::exp((s - r.score) / options_.covariance_temperature);
        const Eigen::Vector3d d(dx * res, dy * res, dj * step);
        m += wt * d * d.transpose();
        wsum += wt;
      }
  }
  m /= wsum;
  m += Eigen::Vector3d(res * res / 12.0, res * res / 12.0, step * step / 12.0).asDiagonal();
  Eigen::Matrix3d j = Eigen::Matrix3d::Identity();
  j.topLeftCorner<2, 2>() = grid.origin().rotation();
  r.covariance = j * m * j.transpose();
  return r;
}

const char* toString(LoopRejection r) {
  switch (r) {
    case LoopRejection::kNone:
      return "accepted";
    case LoopRejection::kNoMatch:
      return "no_match";
    case LoopRejection::kLowScore:
      return "low_score";
    case LoopRejection::kAmbiguous:
      return "ambiguous";
    case LoopRejection::kUnconstrained:
      return "unconstrained";
    case LoopRejection::kInconsistent:
      return "inconsistent";
    case LoopRejection::kBadPrior:
      return "bad_prior";
  }
  return "unknown";
}

LoopClosureVerifier::LoopClosureVerifier(Options o) : options_(o) {
  if (!(o.min_score >= 0.0 && o.min_score <= 1.0))
    throw std::invalid_argument("LoopClosureVerifier: min_score must be in [0, 1]");
  if (!(o.max_ambiguity > 0.0 && o.max_ambiguity <= 1.0))
    throw std::invalid_argument("LoopClosureVerifier: max_ambiguity must be in (0, 1]");
  if (!(std::isfinite(o.max_position_sigma) && o.max_position_sigma >= 0.0))
    throw std::invalid_argument("LoopClosureVerifier: max_position_sigma must be >= 0");
  if (!(std::isfinite(o.max_prior_sigmas) && o.max_prior_sigmas > 0.0))
    throw std::invalid_argument("LoopClosureVerifier: max_prior_sigmas must be > 0");
}

LoopVerdict LoopClosureVerifier::verify(const CorrelativeMatchResult& match, const Pose2& prior,
                                        const Eigen::Matrix3d& prior_covariance) {
  ++counts_.candidates;
  LoopVerdict v;
  auto reject = [&](LoopRejection why, std::size_t& counter) {
    v.reason = why;
    ++counter;
    return v;
  };
  if (!match.matched()) return reject(LoopRejection::kNoMatch, counts_.no_match);
  v.score = match.score;
  v.ambiguity = match.score > 0.0 ? match.second_best_score / match.score : 0.0;
  if (match.score < options_.min_score) return reject(LoopRejection::kLowScore, counts_.low_score);
  if (v.ambiguity > options_.max_ambiguity)
    return reject(LoopRejection::kAmbiguous, counts_.ambiguous);
  if (options_.max_position_sigma > 0.0) {
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> position(
        match.covariance.topLeftCorner<2, 2>(), Eigen::EigenvaluesOnly);
    if (!(std::sqrt(std::max(0.0, position.eigenvalues()[1])) <= options_.max_position_sigma))
      return reject(LoopRejection::kUnconstrained, counts_.unconstrained);
  }

  const bool finite = prior.isFinite() && prior_covariance.allFinite();
  const double asym = (prior_covariance - prior_covariance.transpose()).cwiseAbs().maxCoeff();
  if (!finite || asym > 1e-9 * std::max(1.0, prior_covariance.cwiseAbs().maxCoeff()))
    return reject(LoopRejection::kBadPrior, counts_.bad_prior);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(prior_covariance);
  if (eig.info() != Eigen::Success || !(eig.eigenvalues().minCoeff() > 0.0))
    return reject(LoopRejection::kBadPrior, counts_.bad_prior);
  const Eigen::Vector3d delta(match.pose.x - prior.x, match.pose.y - prior.y,
                              angleDiff(match.pose.theta, prior.theta));
  const Eigen::Vector3d z = eig.eigenvectors().transpose() * delta;
  v.prior_sigmas = std::sqrt((z.array().square() / eig.eigenvalues().array()).sum());
  if (v.prior_sigmas > options_.max_prior_sigmas)
    return reject(LoopRejection::kInconsistent, counts_.inconsistent);

  v.accepted = true;
  v.reason = LoopRejection::kNone;
  ++counts_.accepted;
  return v;
}

}  // namespace tessera::scan_matching
