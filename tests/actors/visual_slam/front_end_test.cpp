// Visual SLAM front end on synthetic inputs: bucketed extraction and depth checks, the matcher's
// ratio and minimum-distance filters, brute force against FLANN, RANSAC PnP with outliers, the
// keyframe rule, and bad input.
#include <tessera/visual_slam/depth_registration.hpp>
#include <tessera/visual_slam/feature_extractor.hpp>
#include <tessera/visual_slam/feature_matcher.hpp>
#include <tessera/visual_slam/keyframe_selector.hpp>
#include <tessera/visual_slam/pose_estimator.hpp>
#include <tessera/visual_slam/tracker.hpp>

#include <catch2/catch.hpp>

#include <opencv2/imgproc.hpp>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>

namespace vs = tessera::visual_slam;

namespace {

vs::PinholeCamera kinect() {
  return {525.0, 525.0, 319.5, 239.5, 640, 480};
}

// A grey image full of random rectangles and discs: corners everywhere.
cv::Mat texturedImage(unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> x(0, 639), y(0, 479), s(4, 30), g(0, 255);
  cv::Mat img(480, 640, CV_8UC1, cv::Scalar(128));
  for (int i = 0; i < 1500; ++i) {
    const cv::Point p(x(rng), y(rng));
    if (i % 2 == 0)
      cv::rectangle(img, p, p + cv::Point(s(rng), s(rng)), cv::Scalar(g(rng)), cv::FILLED);
    else
      cv::circle(img, p, s(rng) / 2, cv::Scalar(g(rng)), cv::FILLED);
  }
  return img;
}

cv::Mat constantDepth(std::uint16_t value) {
  return cv::Mat(480, 640, CV_16UC1, cv::Scalar(value));
}

}  // namespace

TEST_CASE("extractor spreads ORB features over the grid and back-projects them", "[visual_slam]") {
  vs::FeatureExtractorOptions o;
  const vs::FeatureExtractor ex(o, kinect());
  const auto f = ex.extract(texturedImage(1), constantDepth(2000), 1000.0);
  REQUIRE(f.per_cell.size() == 48);
  CHECK(f.cell_budget == 1000 / 48);
  int filled = 0;
  for (int n : f.per_cell) {
    CHECK(n <= f.cell_budget);
    if (n > 0) ++filled;
  }
  CHECK(filled >= 44);  // the outermost cells lose part of their area to the image border
  CHECK(f.size() <= 1000);
  CHECK(f.size() > 600);
  CHECK(f.descriptors.rows == static_cast<int>(f.size()));
  CHECK(f.descriptors.type() == CV_8U);
  CHECK(f.with_depth == f.size());
  for (std::size_t i = 0; i < f.size(); ++i) {
    const auto& kp = f.keypoints[i].pt;
    CHECK(f.points[i].z() == Approx(2.0));
    CHECK(f.points[i].x() == Approx((kp.x - 319.5) * 2.0 / 525.0));
    CHECK(f.points[i].y() == Approx((kp.y - 239.5) * 2.0 / 525.0));
  }
}

TEST_CASE("extractor with SIFT gives float descriptors within the budget", "[visual_slam]") {
  vs::FeatureExtractorOptions o;
  o.type = vs::FeatureType::kSift;
  o.max_features = 480;
  const vs::FeatureExtractor ex(o, kinect());
  const auto f = ex.extract(texturedImage(2), cv::Mat(), 1000.0);
  CHECK(f.descriptors.type() == CV_32F);
  CHECK(f.descriptors.cols == 128);
  CHECK(f.size() > 200);
  for (int n : f.per_cell) CHECK(n <= 10);
  CHECK(f.with_depth == 0);
  CHECK(f.rejects.missing == f.size());
}

TEST_CASE("extractor rejects depth that is missing, out of range or on an edge", "[visual_slam]") {
  const vs::FeatureExtractor ex({}, kinect());
  const cv::Mat img = texturedImage(3);
  // Left half 1 m, right half 3 m: keypoints within the window of column 320 straddle the edge.
  cv::Mat depth = constantDepth(1000);
  depth.colRange(320, 640).setTo(3000);
  const auto f = ex.extract(img, depth, 1000.0);
  std::size_t near_edge = 0;
  for (std::size_t i = 0; i < f.size(); ++i) {
    const int u = static_cast<int>(std::lround(f.keypoints[i].pt.x));
    if (u >= 318 && u <= 321) {
      ++near_edge;
      CHECK(!f.has_depth[i]);
    }
    if (u < 317 || u > 322) CHECK(f.has_depth[i]);
  }
  CHECK(f.rejects.edge >= near_edge);
  // Zero depth: every keypoint missing; too far: out of range.
  CHECK(ex.extract(img, constantDepth(0), 1000.0).rejects.missing > 0);
  const auto far = ex.extract(img, constantDepth(9000), 1000.0);
  CHECK(far.with_depth == 0);
  CHECK(far.rejects.out_of_range == far.size());
}

TEST_CASE("matcher applies the ratio test and the minimum-distance filter", "[visual_slam]") {
  std::mt19937 rng(7);
  cv::Mat train(6, 32, CV_8U);
  cv::randu(train, 0, 256);
  const auto flip = [](cv::Mat row, int from, int count) {
    for (int b = from; b < from + count; ++b) row.at<std::uint8_t>(0, b / 8) ^= 1u << (b % 8);
  };
  // train 2 = train 1 with bits 0..7 flipped: a query with bits 0..3 flipped is 4 from both.
  train.row(1).copyTo(train.row(2));
  flip(train.row(2), 0, 8);
  cv::Mat query(3, 32, CV_8U);
  train.row(0).copyTo(query.row(0));
  flip(query.row(0), 100, 2);  // distance 2 to train 0: the best match
  train.row(1).copyTo(query.row(1));
  flip(query.row(1), 0, 4);  // ambiguous: fails the ratio test
  train.row(3).copyTo(query.row(2));
  flip(query.row(2), 0, 50);  // passes the ratio test, but 50 > max(4 x 2, 30)

  vs::MatchStats stats;
  const vs::FeatureMatcher matcher;
  const auto m = matcher.match(query, train, &stats);
  CHECK(stats.queries == 3);
  CHECK(stats.after_ratio == 2);
  CHECK(stats.best_distance == 2);
  REQUIRE(m.size() == 1);
  CHECK(m[0].queryIdx == 0);
  CHECK(m[0].trainIdx == 0);
  CHECK(vs::descriptorDistance(query, 2, train, 3) == 50);

  vs::FeatureMatcherOptions loose;
  loose.min_distance_factor = 0;  // filter off: the far match stays
  CHECK(vs::FeatureMatcher(loose).match(query, train).size() == 2);
  CHECK(matcher.match(cv::Mat(), train).empty());
  CHECK_THROWS_AS(matcher.match(query, cv::Mat(3, 16, CV_8U, cv::Scalar(0))),
                  std::invalid_argument);
}

TEST_CASE("matcher with FLANN finds the brute-force matches of ORB and SIFT", "[visual_slam]") {
  // Real features of a textured image against the same image shifted by (7, 3) px: both matchers
  // must pair almost every feature with its shifted self (LSH and KD-trees are approximate).
  const cv::Mat img = texturedImage(4);
  cv::Mat shifted(img.size(), img.type(), cv::Scalar(128));
  img(cv::Rect(0, 0, 633, 477)).copyTo(shifted(cv::Rect(7, 3, 633, 477)));
  for (const auto type : {vs::FeatureType::kOrb, vs::FeatureType::kSift}) {
    vs::FeatureExtractorOptions eo;
    eo.type = type;
    eo.max_features = 500;
    const vs::FeatureExtractor ex(eo, kinect());
    const auto a = ex.extract(img, cv::Mat(), 1000.0);
    const auto b = ex.extract(shifted, cv::Mat(), 1000.0);
    REQUIRE(a.size() > 200);
    vs::FeatureMatcherOptions bo, fo;
    fo.algorithm = vs::MatchAlgorithm::kFlann;
    const auto brute = vs::FeatureMatcher(bo).match(a.descriptors, b.descriptors);
    const auto flann = vs::FeatureMatcher(fo).match(a.descriptors, b.descriptors);
    const auto correct = [&](const std::vector<cv::DMatch>& m) {
      std::size_t n = 0;
      for (const auto& d : m) {
        const cv::Point2f moved = a.keypoints[d.queryIdx].pt + cv::Point2f(7, 3);
        if (cv::norm(moved - b.keypoints[d.trainIdx].pt) < 2) ++n;
      }
      return n;
    };
    INFO((type == vs::FeatureType::kOrb ? "ORB" : "SIFT"));
    CHECK(brute.size() > a.size() / 2);
    CHECK(correct(brute) > 0.95 * brute.size());
    CHECK(flann.size() > 0.8 * brute.size());
    CHECK(correct(flann) > 0.95 * flann.size());
    for (std::size_t i = 1; i < flann.size(); ++i) CHECK(flann[i - 1].queryIdx < flann[i].queryIdx);
    CHECK(vs::FeatureMatcher(fo).match(cv::Mat(), b.descriptors).empty());
    CHECK(vs::FeatureMatcher(fo).match(a.descriptors.rowRange(0, 1), b.descriptors).size() <= 1);
  }
  vs::FeatureMatcherOptions bad;
  bad.flann_checks = 0;
  CHECK_THROWS_AS(vs::FeatureMatcher(bad), std::invalid_argument);
}

TEST_CASE("RANSAC iteration count follows k = log(1-p)/log(1-w^m)", "[visual_slam]") {
  CHECK(vs::ransacIterations(0.995, 0.5, 4, 10000) == 83);
  CHECK(vs::ransacIterations(0.995, 0.3, 4, 10000) == 652);
  CHECK(vs::ransacIterations(0.995, 0.3, 4, 100) == 100);
  CHECK(vs::ransacIterations(0.995, 1.0, 4, 100) == 100);
  CHECK(vs::minimalSample(vs::PnpMethod::kAp3p) == 4);
  CHECK(vs::minimalSample(vs::PnpMethod::kEpnp) == 5);
}

TEST_CASE("PnP recovers a known pose from points with 30 % outliers", "[visual_slam]") {
  const auto cam = kinect();
  Eigen::Isometry3d cam_from_world = Eigen::Isometry3d::Identity();
  cam_from_world.linear() =
      Eigen::AngleAxisd(0.3, Eigen::Vector3d(0.2, 1.0, -0.1).normalized()).toRotationMatrix();
  cam_from_world.translation() = Eigen::Vector3d(0.4, -0.2, 0.7);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> ux(-2, 2), uz(2, 6), pu(0, 640), pv(0, 480);
  std::normal_distribution<double> noise(0, 0.3);
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> pixels;
  std::vector<bool> outlier;
  while (points.size() < 300) {
    const Eigen::Vector3d c(ux(rng), 0.75 * ux(rng), uz(rng));
    const Eigen::Vector2d uv = cam.project(c);
    if (!cam.inside(uv)) continue;
    const bool out = points.size() % 10 < 3;
    points.push_back(cam_from_world.inverse() * c);
    pixels.push_back(out ? Eigen::Vector2d(pu(rng), pv(rng))
                         : Eigen::Vector2d(uv.x() + noise(rng), uv.y() + noise(rng)));
    outlier.push_back(out);
  }
  for (auto method : {vs::PnpMethod::kAp3p, vs::PnpMethod::kEpnp, vs::PnpMethod::kIterative}) {
    vs::PoseEstimatorOptions o;
    o.method = method;
    const auto est = vs::PoseEstimator(o, cam).estimate(points, pixels);
    REQUIRE(est.ok);
    const Eigen::Isometry3d err = est.camera_from_world * cam_from_world.inverse();
    CHECK(err.translation().norm() < 0.01);
    CHECK(Eigen::AngleAxisd(err.rotation()).angle() < 0.2 * std::numbers::pi / 180);
    CHECK(est.rms_px < 0.6);
    std::size_t wrong = 0;
    for (int i : est.inliers) wrong += outlier[static_cast<std::size_t>(i)] ? 1 : 0;
    CHECK(est.inliers.size() >= 200);  // 210 true inliers, all within 3 px
    CHECK(wrong <= 3);                 // a random pixel may land near its true projection
    CHECK(est.covariance.diagonal().minCoeff() > 0);
    CHECK(est.covariance.diagonal().maxCoeff() < 1e-3);
  }
}

TEST_CASE("PnP reports failure instead of a pose on hopeless input", "[visual_slam]") {
  const vs::PoseEstimator est({}, kinect());
  CHECK(!est.estimate({}, {}).ok);
  std::vector<Eigen::Vector3d> pts(10, Eigen::Vector3d(0, 0, 1));
  std::vector<Eigen::Vector2d> px(10, Eigen::Vector2d(std::nan(""), 0));
  const auto r = est.estimate(pts, px);
  CHECK(!r.ok);
  CHECK(!r.failure.empty());
  CHECK(!est.estimate(pts, std::vector<Eigen::Vector2d>(3)).ok);
}

TEST_CASE("keyframe rule on hand-made motions", "[visual_slam]") {
  const auto motion = [](double angle, double tx) {
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.linear() = Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitY()).toRotationMatrix();
    t.translation() = Eigen::Vector3d(tx, 0, 0);
    return t;
  };
  CHECK(vs::motionSize(motion(0, 0)) == 0);
  CHECK(vs::motionSize(motion(0.1, 0.2)) == Approx(0.3));
  CHECK(vs::motionSize(motion(3.0, 0)) == Approx(3.0));
  CHECK(vs::motionSize(motion(-3.0, 0.1)) == Approx(3.1));

  vs::KeyframeSelector sel;  // thesis defaults: 4, 0.3, 0.06
  using D = vs::KeyframeDecision;
  CHECK(sel.decide(100, motion(0, 0)) == D::kSkip);
  CHECK(sel.decide(100, motion(0.02, 0.03)) == D::kSkip);          // e = 0.05
  CHECK(sel.decide(100, motion(0.03, 0.04)) == D::kKeyframe);      // e = 0.07
  CHECK(sel.decide(100, motion(0.0, 0.25)) == D::kKeyframe);       // e = 0.25
  CHECK(sel.decide(100, motion(0.1, 0.25)) == D::kDropTooLarge);   // e = 0.35
  CHECK(sel.decide(3, motion(0.03, 0.04)) == D::kDropFewInliers);  // fewer than goodmatch
  CHECK(sel.decide(4, motion(0.03, 0.04)) == D::kKeyframe);
  CHECK(sel.counts().keyframes == 3);
  CHECK(sel.counts().skipped == 2);
  CHECK(sel.counts().dropped_too_large == 1);
  CHECK(sel.counts().dropped_few_inliers == 1);
  CHECK(vs::decisionName(D::kDropTooLarge) == "drop_too_large");
  vs::KeyframeOptions bad;
  bad.e_key = 0.5;
  CHECK_THROWS_AS(vs::KeyframeSelector(bad), std::invalid_argument);
}

TEST_CASE("bad input gives a clear error or a counted skip", "[visual_slam]") {
  auto cam = kinect();
  cam.fx = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(vs::Tracker({}, cam), Catch::Contains("fx"));
  vs::TrackerOptions bad;
  bad.extractor.max_features = 0;
  CHECK_THROWS_WITH(vs::Tracker(bad, kinect()), Catch::Contains("max_features"));
  CHECK_THROWS_AS(vs::FeatureExtractor({}, kinect()).extract(cv::Mat(480, 640, CV_8UC3), {}, 1),
                  std::invalid_argument);

  vs::Tracker tracker({}, kinect());
  const cv::Mat img = texturedImage(5);
  auto r = tracker.track({cv::Mat(), constantDepth(2000), 1000, 0.0});
  CHECK(r.state == vs::TrackingState::kSkipped);
  CHECK(r.skip_reason == "empty image");
  r = tracker.track({cv::Mat(240, 320, CV_8UC1, cv::Scalar(0)), constantDepth(2000), 1000, 0.1});
  CHECK(r.skip_reason == "image is 320x240, the camera 640x480");
  r = tracker.track({img, cv::Mat(240, 320, CV_16UC1, cv::Scalar(0)), 1000, 0.2});
  CHECK(r.skip_reason == "depth is 320x240, the image 640x480");
  r = tracker.track({img, constantDepth(2000), std::nan(""), 0.3});
  CHECK(r.skip_reason == "depth_scale is not a positive number");
  r = tracker.track({img, constantDepth(0), 1000, 0.4});  // no depth: cannot start the map
  CHECK(r.state == vs::TrackingState::kSkipped);
  CHECK_THAT(r.skip_reason, Catch::StartsWith("too few features with depth"));
  r = tracker.track({cv::Mat(480, 640, CV_8UC1, cv::Scalar(0)), constantDepth(2000), 1000, 0.5});
  CHECK(r.state == vs::TrackingState::kSkipped);  // black: no features
  CHECK(tracker.stats().skipped == 6);

  // Started on a flat textured wall; then the same view without depth still tracks (depth is
  // only needed for new map points), a black frame is lost with a finite pose, and the view
  // seen again relocalises.
  r = tracker.track({img, constantDepth(2000), 1000, 0.6});
  CHECK(r.state == vs::TrackingState::kInitialised);
  r = tracker.track({img, constantDepth(0), 1000, 0.7});
  CHECK(r.state == vs::TrackingState::kTracking);
  CHECK(r.camera_to_world.translation().norm() < 1e-3);
  r = tracker.track({cv::Mat(480, 640, CV_8UC1, cv::Scalar(0)), constantDepth(2000), 1000, 0.8});
  CHECK(r.state == vs::TrackingState::kLost);
  CHECK(!r.pose_valid);
  CHECK(r.camera_to_world.matrix().allFinite());
  r = tracker.track({img, constantDepth(2000), 1000, 0.9});
  CHECK(r.state == vs::TrackingState::kRelocalised);
  CHECK(r.camera_to_world.translation().norm() < 1e-3);
  CHECK(tracker.stats().lost == 1);
  CHECK(tracker.stats().relocalised == 1);
}

TEST_CASE("depth registration moves readings into the colour camera", "[visual_slam]") {
  const auto cam = kinect();
  vs::ColorCalibration same{cam, Eigen::Isometry3d::Identity(), "identity"};
  const cv::Mat depth = constantDepth(2000);
  const cv::Mat out = vs::registerDepth(depth, cam, same);
  REQUIRE(out.type() == CV_16UC1);
  CHECK(out.at<std::uint16_t>(240, 320) == 2000);
  CHECK(cv::countNonZero(out) > 0.99 * 640 * 480);
  // A colour camera 5 cm to the right (x) sees a wall at 2 m shifted left by f * b / z ~ 13 px:
  // its rightmost columns get no readings.
  vs::ColorCalibration shifted = same;
  shifted.color_from_depth.translation() = Eigen::Vector3d(-0.05, 0, 0);
  const cv::Mat moved = vs::registerDepth(depth, cam, shifted);
  CHECK(moved.at<std::uint16_t>(240, 320) == 2000);
  CHECK(moved.at<std::uint16_t>(240, 635) == 0);
  CHECK(moved.at<std::uint16_t>(240, 5) == 2000);
  CHECK_THROWS_AS(vs::registerDepth(cv::Mat(480, 640, CV_32F), cam, same), std::invalid_argument);
  // The one decision: only unregistered input with register_depth gets the 7-Scenes calibration.
  CHECK(vs::depthRegistration(false, true).has_value());
  CHECK_FALSE(vs::depthRegistration(false, false).has_value());
  CHECK_FALSE(vs::depthRegistration(true, true).has_value());
  CHECK(vs::TrackerOptions{}.register_depth);
  const auto seven = vs::sevenScenesColorCalibration();
  CHECK(seven.color.fx == 525);
  CHECK(seven.color_from_depth.translation().x() == Approx(-0.0256).margin(1e-4));
}
