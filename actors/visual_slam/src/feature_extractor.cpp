// FeatureExtractor: per-cell ORB/SIFT detection (TBB over cells), whole-image descriptors, and
// the depth lookup with its validity checks (see the header).
#include <tessera/visual_slam/feature_extractor.hpp>

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numeric>
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

// `levels` > 1: a pyramid for the descriptor pass (ORB picks each keypoint's level by its octave);
// detection runs one level at a time, so it asks for a single level.
cv::Ptr<cv::Feature2D> makeOrb(const FeatureExtractorOptions& o, int nfeatures, int threshold,
                               int levels) {
  return cv::ORB::create(nfeatures, static_cast<float>(o.orb_scale_factor), levels,
                         kOrbEdgeThreshold, 0, 2, cv::ORB::HARRIS_SCORE, kOrbPatchSize, threshold);
}

cv::Ptr<cv::Feature2D> makeSift(const FeatureExtractorOptions& o, int nfeatures) {
  return cv::SIFT::create(nfeatures, 3, o.sift_contrast_threshold);
}

// Keypoints of one cell of `image`: detected on the cell plus `margin` (so a keypoint near the
// cell's edge sees its whole neighbourhood), kept when inside the cell, strongest first, at most
// `budget`. `make(n)` makes the detector asked for n keypoints.
template <class Make>
std::vector<cv::KeyPoint> detectCell(const cv::Mat& image, const cv::Rect& cell, int margin,
                                     int budget, const Make& make) {
  const cv::Rect roi = cv::Rect(cell.x - margin, cell.y - margin, cell.width + 2 * margin,
                                cell.height + 2 * margin) &
                       cv::Rect(0, 0, image.cols, image.rows);
  std::vector<cv::KeyPoint> found;
  // Ask for more than the budget: part of what the detector returns lies in the margin.
  make(3 * budget)->detect(image(roi), found);
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
}

// ORB keypoints of one cell over the pyramid: level L detects in the cell's footprint on
// pyramid[L] (a margin of ORB's border at that level) and keeps its quota; coordinates, octave
// and size are then those ORB itself gives a level-L keypoint. A level short of half its quota
// retries with min_fast_threshold.
std::vector<cv::KeyPoint> detectOrbCell(const std::vector<cv::Mat>& pyramid,
                                        const std::vector<int>& quota, const cv::Rect& cell,
                                        const FeatureExtractorOptions& o) {
  std::vector<cv::KeyPoint> out;
  double scale = 1;
  for (std::size_t level = 0; level < pyramid.size(); ++level, scale *= o.orb_scale_factor) {
    const auto at = [&](int v) { return static_cast<int>(std::lround(v / scale)); };
    const cv::Rect c(at(cell.x), at(cell.y), at(cell.x + cell.width) - at(cell.x),
                     at(cell.y + cell.height) - at(cell.y));
    const int q = quota[level];
    if (q < 1 || c.width < 1 || c.height < 1) continue;
    const auto make = [&](int threshold) {
      return [&o, threshold](int n) { return makeOrb(o, n, threshold, 1); };
    };
    auto kept = detectCell(pyramid[level], c, kOrbEdgeThreshold + 1, q, make(o.fast_threshold));
    if (2 * static_cast<int>(kept.size()) < q && o.min_fast_threshold < o.fast_threshold)
      kept = detectCell(pyramid[level], c, kOrbEdgeThreshold + 1, q, make(o.min_fast_threshold));
    for (auto& kp : kept) {
      kp.pt *= static_cast<float>(scale);
      kp.octave = static_cast<int>(level);
      kp.size = static_cast<float>(kOrbPatchSize * scale);
      out.push_back(kp);
    }
  }
  return out;
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
  if (gray.type() != CV_8UC1)
    throw std::invalid_argument("feature extractor: image is not 8-bit grey");
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
  std::vector<std::vector<cv::KeyPoint>> per_cell(static_cast<std::size_t>(cells));
  const auto cellRect = [&](int c) {
    const int col = c % o.grid_cols, row = c / o.grid_cols;
    const int x0 = col * gray.cols / o.grid_cols, x1 = (col + 1) * gray.cols / o.grid_cols;
    const int y0 = row * gray.rows / o.grid_rows, y1 = (row + 1) * gray.rows / o.grid_rows;
    return cv::Rect(x0, y0, x1 - x0, y1 - y0);
  };
  if (o.type == FeatureType::kSift) {
    tbb::parallel_for(0, cells, [&](int c) {
      per_cell[static_cast<std::size_t>(c)] = detectCell(
          gray, cellRect(c), kSiftMargin, out.cell_budget, [&o](int n) { return makeSift(o, n); });
    });
  } else {
    // One pyramid (as ORB builds it: each level resized from the one above) shared by all
    // cells; a cell's budget is split over the levels in proportion to their area, as ORB does.
    std::vector<cv::Mat> pyramid(static_cast<std::size_t>(o.orb_levels));
    pyramid[0] = gray;
    std::vector<double> weight(pyramid.size(), 1.0);
    double total = 1.0;
    for (std::size_t l = 1; l < pyramid.size(); ++l) {
      const double s = std::pow(o.orb_scale_factor, static_cast<double>(l));
      cv::resize(pyramid[l - 1], pyramid[l],
                 cv::Size(static_cast<int>(std::lround(gray.cols / s)),
                          static_cast<int>(std::lround(gray.rows / s))),
                 0, 0, cv::INTER_LINEAR_EXACT);
      weight[l] = 1.0 / (s * s);
      total += weight[l];
    }
    std::vector<int> quota(pyramid.size());
    for (std::size_t l = 0; l < pyramid.size(); ++l)
      quota[l] = static_cast<int>(std::floor(out.cell_budget * weight[l] / total));
    quota[0] += out.cell_budget - std::accumulate(quota.begin(), quota.end(), 0);
    tbb::parallel_for(0, cells, [&](int c) {
      per_cell[static_cast<std::size_t>(c)] = detectOrbCell(pyramid, quota, cellRect(c), o);
    });
  }
  out.per_cell.reserve(per_cell.size());
  for (const auto& kps : per_cell) {
    out.per_cell.push_back(static_cast<int>(kps.size()));
    out.keypoints.insert(out.keypoints.end(), kps.begin(), kps.end());
  }
  if (out.keypoints.empty()) return out;

  // One descriptor pass over the whole image (one pyramid). It may reorder keypoints (ORB
  // groups them by level) and drop some at the image border, so depth comes after.
  const cv::Ptr<cv::Feature2D> describer =
      o.type == FeatureType::kSift ? makeSift(o, 0)
                                   : makeOrb(o, o.max_features, o.fast_threshold, o.orb_levels);
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
