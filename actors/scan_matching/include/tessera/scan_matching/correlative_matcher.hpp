// CorrelativeMatcher: global scan-to-grid matching over a search window by branch and bound on
// a max-filtered grid pyramid (the real-time loop closure idea of Hess et al. 2016), and the
// LoopClosureVerifier that accepts or rejects its matches as loop closures.
//
// Frames and units: metres and radians. Scan points are in the robot (base) frame; poses are
// robot poses in the frame the grid's `origin` is given in ("map", or a submap's frame). The
// search window is a square of ±linear along the grid's cell axes (the map axes when the grid's
// origin has no yaw) and ±angular in heading, around the initial pose.
//
// Score. A candidate pose puts every point into a cell (floor of its coordinates); the score is
// the mean occupancy probability of those cells, in [0, 1]. Unknown cells and cells outside the
// grid count as `unknown_probability`. Probabilities are stored as 8-bit fixed point in units of
// 1/200 (MatchGrid::kScale): ROS percent cells p map exactly to 2p and the default
// unknown_probability 0.1 to 20; float probabilities and other unknown_probability values are
// rounded to the nearest 1/200. Scores are therefore exact integer sums, and branch and bound
// returns the same maximum as exhaustive search.
//
// Candidates. Translations are the initial translation plus whole cells (the grid resolution);
// headings are the initial heading plus whole angular steps, by default the step that moves the
// farthest point by at most one cell: acos(1 − r²/2d²) (Hess et al. eq. 7). The result is
// therefore at cell / angular-step accuracy; a local matcher (ScanMatcher) can refine it.
//
// Branch and bound. Level h of the pyramid holds, per cell, the maximum of the 2^h × 2^h block of
// cells starting there, so the score of a scan on level h at a block corner bounds the score of
// every translation in the block. Depth-first search from the coarsest blocks, best bound first,
// prunes every block whose bound cannot beat the best leaf found (or min_score).
//
// Ambiguity. A second search, with the same bounds, finds the best candidate at a DISTINCT pose:
// farther than exclusion_radius from the best, or turned by more than exclusion_angle. It only
// looks for candidates scoring ≥ second_best_min_ratio · best (and ≥ min_score): anything lower
// is reported as 0, which is exact for any ambiguity threshold above that ratio.
//
// Covariance. A fixed, documented model rather than a likelihood: candidates on the cell /
// angular-step lattice within covariance_radius and covariance_angle_steps of the best are
// weighted by exp((score − best) / covariance_temperature); the covariance is their weighted
// second moment about the best plus the lattice's own variance (step²/12 per axis). A direction
// the scan does not constrain (a corridor's axis) therefore reads as roughly the uniform variance
// of the sampled span, a well-constrained one as about the lattice floor.
//
// Bad input never throws from match(): an empty or inconsistent grid, a scan without finite
// points, a non-positive or non-finite window or a non-finite pose give a result whose status
// says so. Invalid options throw std::invalid_argument from the constructors.
//
// Ownership and threads: GridView borrows cells; MatchGrid owns its pyramid and is immutable
// once built, so one MatchGrid (e.g. per finished submap) can serve concurrent match() calls.
// Memory: a pyramid holds depth()+1 levels of 8-bit cells (levels above 0 padded by 2^h − 1
// per axis), about depth+1 bytes per grid cell — 8 times the int8 grid at depth 7, plus the
// padding (9.4 bytes per cell in all for a 400 × 400 grid at depth 7). A user
// matching against many grids can keep their int8 cells and rebuild pyramids on demand: the
// build is deterministic, so the same cells give the same pyramid and the same matches.
// Levels of 64 KiB and more are mapped on their own (memory::MappedAllocator), so a dropped
// pyramid gives its memory back to the system at once.
// CorrelativeMatcher holds only options. LoopClosureVerifier counts its decisions and is not
// thread-safe.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_map.hpp>
#include <tessera/memory/mapped_allocator.hpp>

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace tessera::scan_matching {

/// A borrowed grid: exactly one of `percent` or `probability` holds width·height cells,
/// row-major, row 0 at the origin's y (the ROS nav_msgs / grid::OccupancyMap / Map.OccupancyGrid
/// layout, so a message's cell bytes can be viewed without a copy).
struct GridView {
  int width = 0;            ///< cells along x
  int height = 0;           ///< cells along y
  double resolution = 0.0;  ///< [m/cell]
  Pose2 origin;             ///< pose of cell (0,0)'s outer corner in the grid's parent frame
  std::span<const std::int8_t> percent;  ///< ROS cells: −1 (or any < 0) unknown, 0..100 %
  std::span<const float> probability;    ///< or probabilities in [0, 1]; NaN = unknown

  static GridView of(const grid::OccupancyMap& map) {
    return {map.width, map.height, map.resolution, map.origin, map.cells, {}};
  }
};

/// Half-widths of the search window around the initial pose.
struct SearchWindow {
  double linear = 0.0;   ///< [m] ±linear along both cell axes; must be > 0
  double angular = 0.0;  ///< [rad] ±angular in heading; must be ≥ 0 (0 = translation only)
};

struct CorrelativeMatcherOptions {
  /// Pyramid levels above full resolution; the coarsest blocks are 2^depth cells wide. 7 (6.4 m
  /// blocks at 5 cm) suits windows of a few metres. 0..10.
  int pyramid_depth = 7;
  /// [rad] angular step; 0 = from the scan: acos(1 − r²/2d²), d = the farthest point's range.
  double angular_step = 0.0;
  /// Upper bound on the headings tried on each side of the initial one; the step is widened when
  /// the window would need more (a guard against a huge window or range).
  int max_angular_steps = 1024;
  /// [m] points farther than this from the robot are dropped (counted in the result).
  double max_range = 30.0;
  /// Lowest score a match may have; lower bests leave the result unmatched. Also the pruning
  /// floor, so raising it speeds up the search. [0, 1].
  double min_score = 0.5;
  /// Probability given to unknown cells and cells outside the grid, [0, 1]. Low, so that a scan
  /// cannot score well by lying in unexplored space.
  double unknown_probability = 0.1;
  /// Second-best search: distinct means farther than exclusion_radius [m] OR turned by more than
  /// exclusion_angle [rad] from the best.
  double exclusion_radius = 0.5;
  double exclusion_angle = 0.35;
  /// The second-best search only looks for scores ≥ this fraction of the best; lower ones are
  /// reported as 0. [0, 1].
  double second_best_min_ratio = 0.5;
  bool compute_second_best = true;
  /// Covariance model (see the header comment): the sampled span [m] and headings per side, and
  /// the score temperature (> 0).
  double covariance_radius = 0.25;
  int covariance_angle_steps = 3;
  double covariance_temperature = 0.02;
  /// kExhaustive scores every candidate (a reference for tests and benchmarks).
  enum class Search { kBranchAndBound, kExhaustive };
  Search search = Search::kBranchAndBound;

  /// The options a profile sets (search is for tests and benchmarks).
  template <class V>
  void visit(V& v) {
    v("pyramid_depth", pyramid_depth, "branch-and-bound pyramid levels (0..10)");
    v("angular_step", angular_step, "[rad] heading step; 0 = from the scan's farthest point");
    v("max_angular_steps", max_angular_steps, "most headings tried on each side");
    v("max_range", max_range, "[m] scan points farther than this are not matched");
    v("min_score", min_score, "lowest match score accepted (also the pruning floor), [0, 1]");
    v("unknown_probability", unknown_probability,
      "probability given to unknown cells, [0, 1]: low, so unexplored space scores badly");
    v("exclusion_radius", exclusion_radius,
      "[m] second best: at least this far from the best (or turned by exclusion_angle)");
    v("exclusion_angle", exclusion_angle, "[rad] second best: or turned at least this much");
    v("second_best_min_ratio", second_best_min_ratio,
      "second best: only scores at least this fraction of the best are searched for");
    v("compute_second_best", compute_second_best, "search for the second best (ambiguity)");
    v("covariance_radius", covariance_radius, "[m] covariance: sampled span");
    v("covariance_angle_steps", covariance_angle_steps, "covariance: headings per side");
    v("covariance_temperature", covariance_temperature, "covariance: score temperature (> 0)");
  }
};

/// Fixed-point occupancy pyramid of one grid, built once and matched against many times.
class MatchGrid {
 public:
  /// Fixed-point scale: a stored value v (0..kScale) is probability v / kScale. 200 makes ROS
  /// percent cells exact (p % is 2p) and fits a byte; float probabilities are rounded to the
  /// nearest 1/200.
  static constexpr int kScale = 200;

  /// Never throws on bad data: a zero-size grid, non-positive or non-finite resolution, a
  /// non-finite origin or cell spans not matching width·height (none or both given) give an
  /// empty() grid with error() saying why. Throws std::invalid_argument for a depth outside
  /// 0..10 or unknown_probability outside [0, 1].
  MatchGrid(const GridView& view, int depth, double unknown_probability);

  /// Why `view` gives an empty() grid (the error() MatchGrid would report), or "" when a
  /// pyramid can be built from it; checks the view without building anything.
  static std::string check(const GridView& view);

  bool empty() const { return levels_.empty(); }
  /// Why the grid is empty; "" when it is not.
  const std::string& error() const { return error_; }
  /// Bytes the grid holds: every level's cells (capacity, 1 byte each) plus the object and
  /// level table.
  std::size_t bytes() const;
  int depth() const { return static_cast<int>(levels_.size()) - 1; }
  int width() const { return width_; }
  int height() const { return height_; }
  double resolution() const { return resolution_; }
  const Pose2& origin() const { return origin_; }
  /// The stored value of unknown cells and cells outside the grid:
  /// round(unknown_probability · kScale).
  std::uint8_t unknownValue() const { return unknown_; }

  /// Level h: the maximum over cells [x, x + 2^h) × [y, y + 2^h) of level 0; any cell index is
  /// allowed (outside the grid reads unknownValue()). Level 0 is the grid itself.
  std::uint8_t at(int level, int x, int y) const {
    const Level& l = levels_[static_cast<std::size_t>(level)];
    const auto u = static_cast<unsigned>(x + l.offset);
    const auto v = static_cast<unsigned>(y + l.offset);
    if (u >= l.width || v >= l.height) return unknown_;
    return l.cells[static_cast<std::size_t>(v) * l.width + u];
  }

 private:
  struct Level {
    int offset = 0;  // stored column/row 0 is cell −offset
    unsigned width = 0, height = 0;
    memory::MappedVector<std::uint8_t> cells;  // unmapped when the pyramid goes
  };
  std::vector<Level> levels_;
  int width_ = 0, height_ = 0;
  double resolution_ = 0.0;
  Pose2 origin_;
  std::uint8_t unknown_ = 0;
  std::string error_;
};

enum class MatchStatus {
  kMatched,        ///< best score ≥ min_score
  kBelowMinScore,  ///< searched, nothing reached min_score
  kEmptyScan,      ///< no finite point within max_range
  kEmptyGrid,      ///< the grid is empty or inconsistent (see MatchGrid::error())
  kBadWindow,      ///< linear ≤ 0, angular < 0, or non-finite
  kBadPose,        ///< non-finite initial pose
};
const char* toString(MatchStatus s);

struct CorrelativeMatchResult {
  MatchStatus status = MatchStatus::kEmptyScan;
  bool matched() const { return status == MatchStatus::kMatched; }
  /// Best pose in the grid's parent frame; the initial pose when not matched.
  Pose2 pose;
  double score = 0.0;  ///< mean hit-cell probability at pose, 0 when not matched
  /// Best score at a distinct pose (see the header comment), 0 when none reaches
  /// max(min_score, second_best_min_ratio · score) or when not computed.
  double second_best_score = 0.0;
  Pose2 second_best_pose;  ///< valid when second_best_score > 0
  /// (x, y, θ) in the parent frame, from the model in the header comment; zero when unmatched.
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  double angular_step = 0.0;      ///< [rad] used
  int points_used = 0;            ///< finite points within max_range
  int points_dropped = 0;         ///< non-finite or beyond max_range
  std::int64_t nodes_scored = 0;  ///< candidates and blocks scored by the search (both passes)
};

class CorrelativeMatcher {
 public:
  using Options = CorrelativeMatcherOptions;
  using Result = CorrelativeMatchResult;

  /// Throws std::invalid_argument naming the first bad option.
  explicit CorrelativeMatcher(Options options = {});
  const Options& options() const { return options_; }

  /// The pyramid for `view` with this matcher's depth and unknown probability.
  MatchGrid precompute(const GridView& view) const;

  /// Best pose of `points` (robot frame) within `window` around `initial` (parent frame).
  Result match(const MatchGrid& grid, std::span<const Eigen::Vector2d> points, const Pose2& initial,
               const SearchWindow& window) const;
  /// One-shot form: builds the pyramid, then matches.
  Result match(const GridView& grid, std::span<const Eigen::Vector2d> points, const Pose2& initial,
               const SearchWindow& window) const {
    return match(precompute(grid), points, initial, window);
  }

  /// Mean probability of the cells the points fall in at `pose` (full resolution, no search):
  /// the score match() maximises. 0 for an empty grid, no usable points or a non-finite pose.
  double score(const MatchGrid& grid, std::span<const Eigen::Vector2d> points,
               const Pose2& pose) const;

 private:
  Options options_;
};

struct LoopClosureVerifierOptions {
  double min_score = 0.55;  ///< reject matches scoring below this, [0, 1]
  /// Reject as ambiguous when second_best_score / score exceeds this (a long corridor, a
  /// repeated room). (0, 1].
  double max_ambiguity = 0.9;
  /// [m] Reject as unconstrained when the match's largest position standard deviation (from its
  /// covariance) exceeds this: a scan that slides along a corridor, or past the edge of the
  /// submap, scores well at the wrong place without a distinct second best. 0 = off.
  double max_position_sigma = 0.0;
  /// Reject as inconsistent when the match lies more than this many standard deviations of the
  /// prior covariance from the prior pose (Mahalanobis distance in x, y, θ). > 0.
  double max_prior_sigmas = 3.0;

  template <class V>
  void visit(V& v) {
    v("min_score", min_score, "lowest match score accepted, [0, 1]");
    v("max_ambiguity", max_ambiguity, "reject when second best / best exceeds this, (0, 1]");
    v("max_position_sigma", max_position_sigma,
      "[m] reject matches whose largest position std exceeds this (corridors, submap edges); "
      "0 = off");
    v("max_prior_sigmas", max_prior_sigmas,
      "reject matches farther than this from the prior, in its standard deviations");
  }
};

enum class LoopRejection {
  kNone,           ///< accepted
  kNoMatch,        ///< the matcher found nothing (any status other than kMatched)
  kLowScore,       ///< score < min_score
  kAmbiguous,      ///< second-best / best > max_ambiguity
  kUnconstrained,  ///< the match's position sigma exceeds max_position_sigma
  kInconsistent,   ///< too far from the prior
  kBadPrior,       ///< prior pose non-finite or covariance not symmetric positive definite
};
const char* toString(LoopRejection r);

struct LoopVerdict {
  bool accepted = false;
  LoopRejection reason = LoopRejection::kNoMatch;
  double score = 0.0;
  double ambiguity = 0.0;     ///< second_best_score / score (0 when unmatched)
  double prior_sigmas = 0.0;  ///< Mahalanobis distance of the match from the prior
};

/// Decisions so far, by reason.
struct LoopVerifierCounts {
  std::size_t candidates = 0;
  std::size_t accepted = 0;
  std::size_t no_match = 0;
  std::size_t low_score = 0;
  std::size_t ambiguous = 0;
  std::size_t unconstrained = 0;
  std::size_t inconsistent = 0;
  std::size_t bad_prior = 0;
};

class LoopClosureVerifier {
 public:
  using Options = LoopClosureVerifierOptions;

  /// Throws std::invalid_argument naming the first bad option.
  explicit LoopClosureVerifier(Options options = {});
  const Options& options() const { return options_; }

  /// Judges `match` against the prior belief (pose and covariance (x, y, θ) in the same frame as
  /// match.pose, normally the initial pose given to the matcher). Checks in order: no match,
  /// low score, ambiguous, unconstrained, bad prior, inconsistent. Never throws; counts the
  /// decision.
  LoopVerdict verify(const CorrelativeMatchResult& match, const Pose2& prior,
                     const Eigen::Matrix3d& prior_covariance);

  const LoopVerifierCounts& counts() const { return counts_; }

 private:
  Options options_;
  LoopVerifierCounts counts_;
};

}  // namespace tessera::scan_matching
