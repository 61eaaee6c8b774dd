// FeatureExtractor: per-cell ORB/SIFT detection (TBB over cells), whole-image descriptors, and
// the depth lookup with its validity checks (see the header).
#include <tessera/visual_slam/feature_extractor.hpp>

#include <opencv2/features2d.hpp>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace tessera::visual_slam {

namespace {

// ORB's border at level 0 and the patch its orientation and descriptor use (ORB-SLAM's values:
// a 19 px border keeps more keypoints near cell and image edges than OpenCV's default 31).
constexpr int kOrbEdgeThreshold = 19;
constexpr int kOrbPatchSize = 31;
// SIFT needs a few pixels beyond its extrema and its 16 x 16 descriptor window.
constexpr int kSiftMargin = 20;

cv::Ptr<cv::Feature2D> makeOrb(const FeatureExtractorOptions& o, int nfeatures, int threshold) {
  return cv::ORB::create(nfeatures, static_cast<float>(o.orb_scale_factor), o.orb_levels,
                         kOrbEdgeThreshold, 0, 2, cv::ORB::HARRIS_SCORE, kOrbPatchSize,
                         threshold);
}

cv::Ptr<cv::Feature2D> makeSift(const FeatureExtractorOptions& o, int nfeatures) {
  return cv::SIFT::create(nfeatures, 3, o.sift_contrast_threshold);
}

// Keypoints of one cell: detected on the cell plus `margin` (so a keypoint near the cell's edge
// sees its whole neighbourhood), kept when inside the cell, strongest first, at most `budget`.
std::vector<cv::KeyPoint> detectCell(const cv::Mat& gray, const cv::Rect& cell, int margin,
                                     int budget, const FeatureExtractorOptions& o) {
  const cv::Rect roi =
      cv::Rect(cell.x - margin, cell.y - margin, cell.width + 2 * margin,
               cell.height + 2 * margin) &
      cv::Rect(0, 0, gray.cols, gray.rows);
  const auto run = [&](const cv::Ptr<cv::Feature2D>& detector) {
    std::vector<cv::KeyPoint> found;
    detector->detect(gray(roi), found);
    std::vector<cv::KeyPoint> kept;
    kept.reserve(found.size());
    for (auto kp : found) {
      kp.pt.x += static_cast<float>(roi.x);
      kp.pt.y += static_cast<float>(roi.y);
      if (cell.contains(cv::Point(static_cast<int>(kp.pt.x), static_cast<int>(kp.pt.y))))
        kept.push_back(kp);
    }
    std::sort(kept.begin(), kept.end(),
              [](const cv::KeyPoint& a, const cv::KeyPoint& b) { return a.response > b.response; });
    if (static_cast<int>(kept.size()) > budget) kept.resize(static_cast<std::size_t>(budget));
    return kept;
  };
  // Ask for more than the budget: part of what the detector returns lies in the margin.
  const int ask = 3 * budget;
  if (o.type == FeatureType::kSift) return run(makeSift(o, ask));
  auto kept = run(makeOrb(o, ask, o.fast_threshold));
  if (2 * static_cast<int>(kept.size()) < budget && o.min_fast_threshold < o.fast_threshold)
    kept = run(makeOrb(o, ask, o.min_fast_threshold));
  return kept;
}

}  // namespace

void FeatureExtractorOptions::validate() const {
  const auto bad = [](const std::string& what) {
    throw std::invalid_argument("feature extractor: " + what);
  };
  if (max_features < 1) bad("max_features must be >= 1");
  if (grid_cols < 1 || grid_rows < 1) bad("grid_cols and grid_rows must be >= 1");
  if (orb_levels < 1) bad("orb_levels must be >= 1");
  if (!(orb_scale_factor > 1.0) || !std::isfinite(orb_scale_factor))
    bad("orb_scale_factor must be > 1");
  if (fast_threshold < 1 || min_fast_threshold < 1)
    bad("fast_threshold and min_fast_threshold must be >= 1");
  if (!(sift_contrast_threshold > 0)) bad("sift_contrast_threshold must be > 0");
  if (!(min_depth >= 0) || !(max_depth > min_depth) || !std::isfinite(max_depth))
    bad("need 0 <= min_depth < max_depth (finite)");
  if (depth_window < 0) bad("depth_window must be >= 0");
  if (!(depth_edge_abs >= 0) || !(depth_edge_rel >= 0))
    bad("depth_edge_abs and depth_edge_rel must be >= 0");
}

FeatureExtractor::FeatureExtractor(const FeatureExtractorOptions& options,
                                   const PinholeCamera& camera)
    : options_(options), camera_(camera) {
  options_.validate();
  camera_.validate();
}

Features FeatureExtractor::extract(const cv::Mat& gray, const cv::Mat& depth,
                                   double depth_scale) const {
  const auto& o = options_;
  if (gray.empty()) throw std::invalid_argument("feature extractor: empty image");
  if (gray.type() != CV_8UC1) throw std::invalid_argument("feature extractor: image is not 8-bit grey");
  if (gray.cols != camera_.width || gray.rows != camera_.height)
    throw std::invalid_argument("feature extractor: image is " + std::to_string(gray.cols) + "x" +
                                std::to_string(gray.rows) + ", the camera " +
                                std::to_string(camera_.width) + "x" +
                                std::to_string(camera_.height));
  if (!depth.empty()) {
    if (depth.type() != CV_16UC1)
      throw std::invalid_argument("feature extractor: depth is not 16-bit single-channel");
    if (depth.size() != gray.size())
      throw std::invalid_argument("feature extractor: depth size differs from the image's");
    if (!(depth_scale > 0) || !std::isfinite(depth_scale))
      throw std::invalid_argument("feature extractor: depth_scale must be > 0");
  }

  Features out;
  const int cells = o.grid_cols * o.grid_rows;
  out.cell_budget = std::max(1, o.max_features / cells);
  const int margin =
      o.type == FeatureType::kSift
          ? kSiftMargin
          : static_cast<int>(std::ceil(kOrbEdgeThreshold *
                                       std::pow(o.orb_scale_factor, o.orb_levels - 1))) + 1;
  std::vector<std::vector<cv::KeyPoint>> per_cell(static_cast<std::size_t>(cells));
  tbb::parallel_for(0, cells, [&](int c) {
    const int col = c % o.grid_cols, row = c / o.grid_cols;
    const int x0 = col * gray.cols / o.grid_cols, x1 = (col + 1) * gray.cols / o.grid_cols;
    const int y0 = row * gray.rows / o.grid_rows, y1 = (row + 1) * gray.rows / o.grid_rows;
    per_cell[static_cast<std::size_t>(c)] =
        detectCell(gray, cv::Rect(x0, y0, x1 - x0, y1 - y0), margin, out.cell_budget, o);
  });
  out.per_cell.reserve(per_cell.size());
  for (const auto& kps : per_cell) {
    out.per_cell.push_back(static_cast<int>(kps.size()));
    out.keypoints.insert(out.keypoints.end(), kps.begin(), kps.end());
  }
  if (out.keypoints.empty()) return out;

  // One descriptor pass over the whole image (one pyramid). It may reorder keypoints (ORB
  // groups them by level) and drop some at the image border, so depth comes after.
  const cv::Ptr<cv::Feature2D> describer =
      o.type == FeatureType::kSift ? makeSift(o, 0) : makeOrb(o, o.max_features, o.fast_threshold);
  describer->compute(gray, out.keypoints, out.descriptors);

  const std::size_t n = out.keypoints.size();
  out.points.assign(n, Eigen::Vector3d::Zero());
  out.has_depth.assign(n, 0);
  if (depth.empty()) {
    out.rejects.missing = n;
    return out;
  }
  const int r = o.depth_window;
  for (std::size_t i = 0; i < n; ++i) {
    const cv::Point2f& pt = out.keypoints[i].pt;
    const int u = std::clamp(static_cast<int>(std::lround(pt.x)), 0, depth.cols - 1);
    const int v = std::clamp(static_cast<int>(std::lround(pt.y)), 0, depth.rows - 1);
    const std::uint16_t d = depth.at<std::uint16_t>(v, u);
    if (d == 0) {
      ++out.rejects.missing;
      continue;
    }
    const double z = d / depth_scale;
    if (z < o.min_depth || z > o.max_depth) {
      ++out.rejects.out_of_range;
      continue;
    }
    int valid = 0, total = 0;
    double lo = z, hi = z;
    for (int y = std::max(0, v - r); y <= std::min(depth.rows - 1, v + r); ++y) {
      const auto* rowp = depth.ptr<std::uint16_t>(y);
      for (int x = std::max(0, u - r); x <= std::min(depth.cols - 1, u + r); ++x) {
        ++total;
        const double zz = rowp[x] / depth_scale;
        if (rowp[x] == 0 || zz < o.min_depth || zz > o.max_depth) continue;
        ++valid;
        lo = std::min(lo, zz);
        hi = std::max(hi, zz);
      }
    }
    if (2 * valid < total || hi - lo > o.depth_edge_abs + o.depth_edge_rel * z) {
      ++out.rejects.edge;
      continue;
    }
    out.points[i] = camera_.backProject(pt.x, pt.y, z);
    out.has_depth[i] = 1;
    ++out.with_depth;
  }
  return out;
}

}  // namespace tessera::visual_slam
