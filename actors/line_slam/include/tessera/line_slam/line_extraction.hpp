// Line features from planar laser scans: the AIEPF extractor of docs/algorithms.md#line-extraction
// (seed 001), an iterative end-point fit (split-and-merge) whose clusters are fitted by weighted
// total least squares and split by two-cluster fuzzy c-lines, followed by a merge of collinear
// neighbours.
//
// Lines are in polar (Hessian) form in the frame of the input points: every point p on the line
// satisfies p·n(φ) = r with n(φ) = (cos φ, sin φ); r ≥ 0 [m], φ in (−π, π] [rad]. The 2x2
// covariance is over (r, φ). Segment end points are the projections of the first and last point
// of the segment (in scan order) onto the fitted line. Plain C++ over Eigen; no allocation
// beyond the returned vectors; not thread-safe per extractor object (it has none: extract() is
// const and reentrant).
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_grid.hpp>

#include <Eigen/Core>

#include <cstddef>
#include <span>
#include <vector>

namespace tessera::line_slam {

/// A fitted line: polar parameters, their covariance and the fit's residual.
struct LineFit {
  double r = 0.0;    ///< [m] distance from the frame origin, >= 0
  double phi = 0.0;  ///< [rad] direction of the normal, (−π, π]
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Zero();  ///< over (r, φ)
  double mse = 0.0;           ///< weighted mean squared point distance [m²]
  double max_distance = 0.0;  ///< largest point distance [m]
  bool valid = false;         ///< false for < 2 points, zero total weight or coincident points

  Eigen::Vector2d normal() const;
  Eigen::Vector2d direction() const;  ///< n rotated by +90°
  /// Signed distance of p from the line (positive on the normal's side beyond r).
  double distance(const Eigen::Vector2d& p) const;
};

/// A line segment: a LineFit plus its extent.
struct LineSegment {
  LineFit line;
  Eigen::Vector2d p0 = Eigen::Vector2d::Zero();  ///< [m] first end point (scan order)
  Eigen::Vector2d p1 = Eigen::Vector2d::Zero();  ///< [m] last end point
  int first = 0;                                 ///< index of the first point
  int last = 0;                                  ///< index of the last point (inclusive)

  double length() const { return (p1 - p0).norm(); }
  int points() const { return last - first + 1; }
};

/// Weighted total least squares (docs/algorithms.md#line-extraction): x̄, ȳ weighted means,
/// φ = ½·atan2(−2 S_xy, S_yy − S_xx), r = x̄ cos φ + ȳ sin φ, normalised to r ≥ 0.
/// `weights` may be empty (all 1); otherwise one non-negative weight per point. The covariance
/// assumes isotropic point noise of std `point_sigma[j]` (or `sigma` for all when the span is
/// empty), inflated by the residual when the points scatter more than that.
LineFit fitLineWtls(std::span<const Eigen::Vector2d> points, std::span<const double> weights,
                    double sigma, std::span<const double> point_sigma = {});

/// The line (r, φ) with r normalised to >= 0 (φ turned by π when r < 0) and φ wrapped.
void normalizeLine(double& r, double& phi);

/// A segment given in frame B expressed in frame A, where `pose` is B in A (e.g. a laser-frame
/// segment and the laser mount, or a robot-frame segment and the robot pose). The covariance is
/// carried through the Jacobian of (r, φ) (the pose is taken as exact).
LineSegment transformSegment(const LineSegment& s, const Pose2& pose);

struct LineExtractorOptions {
  double range_sigma = 0.01;         ///< [m] range noise std of one beam
  double range_sigma_rel = 0.0;      ///< extra noise std per metre of range [m/m]
  double breakpoint_distance = 0.2;  ///< [m] neighbours farther apart start a new cluster
  double breakpoint_factor = 3.0;    ///< ... or farther than this × r·Δangle (long ranges)
  double split_mse = 4e-4;           ///< [m²] split while the mean squared error exceeds this
  double split_max_distance = 0.05;  ///< [m] ... or while a point is farther than this
  int fuzzy_iterations = 10;         ///< fuzzy c-lines iterations per split
  double fuzzy_exponent = 2.0;       ///< fuzzifier m (> 1): weights are u^m
  double fuzzy_far_distance = 0.3;   ///< [m] penalty distance: a point farther from both lines
                                     ///< is treated as noise (its membership shrinks)
  int min_points = 6;                ///< segments with fewer points are dropped
  double min_length = 0.3;           ///< [m] shorter segments are dropped
  double merge_angle = 0.05;         ///< [rad] neighbours within this angle ...
  double merge_distance = 0.05;      ///< [m] ... and r difference are merge candidates; the
                                     ///< merged fit must still pass the split thresholds
  double max_range = 30.0;           ///< [m] farther returns are not used
  bool split_fuzzy = true;           ///< false: split at the farthest point (plain IEPF)

  template <class V>
  void visit(V& v) {
    v("range_sigma", range_sigma, "range noise std of one beam [m]");
    v("range_sigma_rel", range_sigma_rel, "extra range noise std per metre of range [m/m]");
    v("breakpoint_distance", breakpoint_distance,
      "neighbouring points farther apart than this start a new cluster [m]");
    v("breakpoint_factor", breakpoint_factor,
      "... or farther apart than this times range x angle increment");
    v("split_mse", split_mse, "split a cluster while its mean squared error exceeds this [m^2]");
    v("split_max_distance", split_max_distance,
      "... or while one of its points is farther than this from the fit [m]");
    v("fuzzy_iterations", fuzzy_iterations, "fuzzy c-lines iterations per split");
    v("fuzzy_exponent", fuzzy_exponent, "fuzzifier m (> 1)");
    v("fuzzy_far_distance", fuzzy_far_distance,
      "fuzzy penalty distance [m]: points farther from both lines count as noise");
    v("min_points", min_points, "segments with fewer points are dropped");
    v("min_length", min_length, "segments shorter than this are dropped [m]");
    v("merge_angle", merge_angle, "neighbouring segments within this angle may merge [rad]");
    v("merge_distance", merge_distance, "... and within this r difference [m]");
    v("max_range", max_range, "returns farther than this are not used [m]");
    v("split_fuzzy", split_fuzzy, "split by fuzzy c-lines (true) or at the farthest point");
  }
};

/// Counts of what one extraction did with its input.
struct LineExtractionStats {
  std::size_t points = 0;         ///< valid points used
  std::size_t invalid_beams = 0;  ///< NaN, below range_min, negative
  std::size_t no_return = 0;      ///< +inf, >= range_max or > max_range
  std::size_t clusters = 0;
  std::size_t splits = 0;
  std::size_t merges = 0;
  std::size_t dropped_segments = 0;  ///< too short or too few points
};

class LineExtractor {
 public:
  /// Throws std::invalid_argument naming the first bad option.
  explicit LineExtractor(LineExtractorOptions options = {});

  /// Segments of one sweep, in the sensor frame, in scan order.
  std::vector<LineSegment> extract(const grid::RangeScan& scan,
                                   LineExtractionStats* stats = nullptr) const;
  /// Segments of an ordered point sequence (e.g. a scan already in Cartesian form);
  /// `sigmas` (may be empty) gives each point's noise std, otherwise range_sigma.
  std::vector<LineSegment> extract(std::span<const Eigen::Vector2d> points,
                                   std::span<const double> sigmas = {},
                                   LineExtractionStats* stats = nullptr) const;

  /// Two-cluster fuzzy c-lines split of points[begin, end): returns the index k in (begin, end)
  /// such that [begin, k) and [k, end) are the two lines' contiguous point runs, or -1 when the
  /// run cannot be split (too few points).
  int fuzzySplit(std::span<const Eigen::Vector2d> points, std::span<const double> sigmas, int begin,
                 int end) const;

  const LineExtractorOptions& options() const { return options_; }

 private:
  LineFit fit(std::span<const Eigen::Vector2d> points, std::span<const double> sigmas, int begin,
              int end) const;
  bool needsSplit(const LineFit& f) const;

  LineExtractorOptions options_;
};

}  // namespace tessera::line_slam
