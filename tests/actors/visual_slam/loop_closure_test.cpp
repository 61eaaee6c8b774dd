// Loop closure core: geometric verification (direct-index matching, PnP, 3D check, covariance) on
// a synthetic textured wall seen from two poses (a true loop with a known relative pose; unrelated
// views and shuffled 3D points rejected), bad views, and the LoopDetector over a camera that walks
// along the wall and comes back (bootstrapped vocabulary, loops found only at the revisit).
#include <tessera/visual_slam/loop_detector.hpp>
#include <tessera/visual_slam/loop_verifier.hpp>

#include "synthetic_wall.hpp"

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <string>

namespace vs = tessera::visual_slam;

namespace {

using tessera::test::cameraAt;
using tessera::test::kCamera;
using tessera::test::view;
using tessera::test::Wall;

std::shared_ptr<const vs::Vocabulary> vocabularyFor(const std::vector<vs::LoopView>& views) {
  std::vector<cv::Mat> images;
  for (const auto& v : views) images.push_back(v.descriptors);
  vs::VocabularyTrainOptions t;
  t.k = 8;
  t.levels = 4;
  return std::make_shared<const vs::Vocabulary>(vs::Vocabulary::train(images, t));
}

void index(const vs::Vocabulary& voc, vs::LoopView& v, int depth) {
  vs::BowVector bow;
  voc.transform(v.descriptors, bow, v.features, depth);
}

double angleOf(const Eigen::Matrix3d& R) {
  return Eigen::AngleAxisd(R).angle();
}

}  // namespace

TEST_CASE("LoopVerifier accepts a true loop with its relative pose", "[loop_closure]") {
  const Wall wall(1);
  const Eigen::Isometry3d candidate_pose = cameraAt(3.0);
  const Eigen::Isometry3d query_pose = cameraAt(3.25, 0.08, 0.1);
  const double sigma = GENERATE(0.0, 0.005);
  vs::LoopView candidate = view(wall, candidate_pose, 2, sigma);
  vs::LoopView query = view(wall, query_pose, 3, sigma);
  const auto voc = vocabularyFor({candidate, query, view(wall, cameraAt(8), 4)});
  const vs::LoopVerifierOptions o;
  index(*voc, candidate, o.direct_depth);
  index(*voc, query, o.direct_depth);

  const vs::LoopVerifier verifier(o, kCamera);
  const auto r = verifier.verify(query, candidate);
  INFO("sigma " << sigma << " matches " << r.matches << " inliers " << r.inliers << " rms "
                << r.rms_px << " reason " << vs::rejectionName(r.rejection));
  REQUIRE(r.accepted);
  CHECK(r.inliers >= o.min_inliers);
  CHECK(r.depth_agreement > 0.9);
  const Eigen::Isometry3d truth = candidate_pose.inverse() * query_pose;
  const Eigen::Isometry3d err = truth.inverse() * r.candidate_from_query;
  CHECK(err.translation().norm() < 0.01);
  CHECK(angleOf(err.rotation()) < 0.2 * M_PI / 180);
  // The covariance is symmetric positive definite and at least the floor.
  const Eigen::Matrix<double, 6, 6> c = r.covariance;
  CHECK((c - c.transpose()).cwiseAbs().maxCoeff() < 1e-12);
  CHECK(c.llt().info() == Eigen::Success);
  CHECK(c(0, 0) >= o.min_sigma_translation * o.min_sigma_translation);
  CHECK(c(5, 5) >= o.min_sigma_rotation * o.min_sigma_rotation);
  CHECK(std::sqrt(c(0, 0)) < 0.05);
}

TEST_CASE("LoopVerifier rejects unrelated views and shuffled points", "[loop_closure]") {
  const Wall wall(1), other(99);
  vs::LoopView candidate = view(wall, cameraAt(3.0), 2);
  vs::LoopView query = view(wall, cameraAt(3.2), 3);
  vs::LoopView unrelated = view(other, cameraAt(3.0), 4);
  const auto voc = vocabularyFor({candidate, query, unrelated});
  const vs::LoopVerifierOptions o;
  for (auto* v : {&candidate, &query, &unrelated}) index(*voc, *v, o.direct_depth);
  const vs::LoopVerifier verifier(o, kCamera);

  SECTION("another wall: descriptors do not match") {
    const auto r = verifier.verify(query, unrelated);
    CHECK_FALSE(r.accepted);
    CHECK(r.rejection == vs::LoopRejection::kTooFewMatches);
  }
  SECTION("the same descriptors on shuffled 3D points: no consistent pose") {
    vs::LoopView shuffled = candidate;
    std::mt19937 rng(7);
    std::shuffle(shuffled.points.begin(), shuffled.points.end(), rng);
    const auto r = verifier.verify(query, shuffled);
    INFO("matches " << r.matches << " inliers " << r.inliers << " reason "
                    << vs::rejectionName(r.rejection));
    CHECK(r.matches >= o.min_matches);
    CHECK_FALSE(r.accepted);
  }
  SECTION("a different place on the same wall: no overlap") {
    vs::LoopView far = view(wall, cameraAt(9.0), 5);
    index(*voc, far, o.direct_depth);
    CHECK_FALSE(verifier.verify(query, far).accepted);
  }
}

namespace {

// `v` without the features whose pixel fails `keep` (the direct index is rebuilt by the caller).
template <class Keep>
vs::LoopView keepOnly(const vs::LoopView& v, Keep&& keep) {
  vs::LoopView out;
  std::vector<int> rows;
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (!keep(v.pixels[i])) continue;
    out.pixels.push_back(v.pixels[i]);
    out.points.push_back(v.points[i]);
    rows.push_back(static_cast<int>(i));
  }
  out.descriptors = cv::Mat(static_cast<int>(rows.size()), 32, CV_8UC1);
  for (std::size_t r = 0; r < rows.size(); ++r)
    v.descriptors.row(rows[r]).copyTo(out.descriptors.row(static_cast<int>(r)));
  return out;
}

}  // namespace

TEST_CASE("LoopVerifier rejects inliers bunched in part of the image", "[loop_closure]") {
  const Wall wall(1);
  vs::LoopView candidate = view(wall, cameraAt(3.0), 2);
  const vs::LoopView full = view(wall, cameraAt(3.25, 0.08, 0.1), 3);
  // Only the left half of the query image: at most 8 of the 16 cells.
  vs::LoopView query = keepOnly(full, [](const Eigen::Vector2d& px) { return px.x() < 320; });
  const auto voc = vocabularyFor({candidate, full});
  vs::LoopVerifierOptions o;
  index(*voc, candidate, o.direct_depth);
  index(*voc, query, o.direct_depth);

  const auto loose = vs::LoopVerifier(o, kCamera).verify(query, candidate);
  INFO("inliers " << loose.inliers << " coverage " << loose.coverage << " reason "
                  << vs::rejectionName(loose.rejection));
  REQUIRE(loose.accepted);
  CHECK(loose.coverage > 0.25);
  CHECK(loose.coverage <= 0.5);
  o.min_coverage = 0.6;
  const auto strict = vs::LoopVerifier(o, kCamera).verify(query, candidate);
  CHECK_FALSE(strict.accepted);
  CHECK(strict.rejection == vs::LoopRejection::kLowCoverage);
}

TEST_CASE("LoopVerifier rejects a loop whose PnP and 3D poses disagree", "[loop_closure]") {
  const Wall wall(1);
  vs::LoopView candidate = view(wall, cameraAt(3.0), 2);
  vs::LoopView query = view(wall, cameraAt(3.25, 0.08, 0.1), 3);
  const auto voc = vocabularyFor({candidate, query});
  vs::LoopVerifierOptions o;
  index(*voc, candidate, o.direct_depth);
  index(*voc, query, o.direct_depth);

  const auto good = vs::LoopVerifier(o, kCamera).verify(query, candidate);
  REQUIRE(good.accepted);
  CHECK(good.pose_disagreement_m < 0.02);
  CHECK(good.fit_rms_m < 0.02);

  // A depth scale error of 3 % in the query (a badly calibrated sensor): each point still passes
  // the 3D check, but the 3D fit moves ~9 cm along the optical axis while PnP, driven by the
  // reprojections, does not follow.
  for (auto& p : query.points) p *= 1.03;
  const auto scaled = vs::LoopVerifier(o, kCamera).verify(query, candidate);
  INFO("disagreement " << scaled.pose_disagreement_m << " m, depth agreement "
                       << scaled.depth_agreement << " reason "
                       << vs::rejectionName(scaled.rejection));
  REQUIRE(scaled.accepted);
  CHECK(scaled.pose_disagreement_m > 0.03);
  o.max_pose_disagreement_m = 0.03;
  const auto strict = vs::LoopVerifier(o, kCamera).verify(query, candidate);
  CHECK_FALSE(strict.accepted);
  CHECK(strict.rejection == vs::LoopRejection::kPoseDisagrees);
}

TEST_CASE("LoopVerifier and LoopView handle bad input", "[loop_closure]") {
  const Wall wall(1);
  vs::LoopView good = view(wall, cameraAt(3.0), 2);
  const vs::LoopVerifier verifier({}, kCamera);
  CHECK(good.check().empty());

  vs::LoopView v = good;
  v.points.pop_back();
  CHECK_FALSE(v.check().empty());
  CHECK_FALSE(verifier.verify(v, good).accepted);

  v = good;
  v.pixels[3].x() = std::numeric_limits<double>::quiet_NaN();
  CHECK(v.check() == "non-finite pixel");

  v = good;
  v.descriptors = cv::Mat(good.descriptors.rows, 16, CV_8UC1, cv::Scalar(0));
  CHECK_FALSE(v.check().empty());

  v = good;
  v.features[0] = {static_cast<int>(v.size())};
  CHECK(v.check() == "feature index out of range");

  const vs::LoopView empty;
  CHECK(empty.check().empty());
  CHECK(verifier.verify(empty, good).rejection == vs::LoopRejection::kTooFewMatches);

  vs::LoopVerifierOptions bad;
  bad.ratio = 0;
  CHECK_THROWS_AS(vs::LoopVerifier(bad, kCamera), std::invalid_argument);
  bad = {};
  bad.pnp.reprojection_error = -1;
  CHECK_THROWS_AS(vs::LoopVerifier(bad, kCamera), std::invalid_argument);
}

namespace {
// A vocabulary bootstrapped on the first 12 keyframes: small, for the walk below.
vs::LoopDetectorOptions bootstrapOptions() {
  vs::LoopDetectorOptions o;
  o.bootstrap_keyframes = 12;
  o.bootstrap_k = 8;
  o.bootstrap_levels = 4;
  return o;
}
// Out along the wall in 0.4 m steps (x 1 ... 9.4), then back to the start.
std::vector<double> outAndBack() {
  std::vector<double> xs;
  for (int i = 0; i < 22; ++i) xs.push_back(1.0 + 0.4 * i);
  for (int i = 0; i < 6; ++i) xs.push_back(1.05 + 0.4 * i);
  return xs;
}
}  // namespace

TEST_CASE("LoopDetector bootstraps a vocabulary and closes the loop at the revisit",
          "[loop_closure]") {
  const Wall wall(1);
  const vs::LoopDetectorOptions o = bootstrapOptions();
  vs::LoopDetector detector(o, nullptr);
  const std::vector<double> xs = outAndBack();
  std::vector<vs::LoopQuery> queries;
  std::vector<Eigen::Isometry3d> poses;
  for (std::size_t i = 0; i < xs.size(); ++i) {
    poses.push_back(cameraAt(xs[i], 0.02 * std::sin(static_cast<double>(i))));
    vs::LoopKeyframe k{static_cast<std::int64_t>(i), kCamera,
                       view(wall, poses.back(), static_cast<std::uint32_t>(100 + i))};
    for (auto& q : detector.add(std::move(k))) queries.push_back(q);
    if (i + 1 < static_cast<std::size_t>(o.bootstrap_keyframes)) CHECK(queries.empty());
  }
  // One bad keyframe: counted, skipped.
  vs::LoopKeyframe bad{99, kCamera, view(wall, cameraAt(2), 1)};
  bad.view.points.pop_back();
  std::string why;
  CHECK(detector.add(std::move(bad), &why).empty());
  CHECK_FALSE(why.empty());

  const auto& s = detector.stats();
  CHECK(s.bootstrapped);
  CHECK(s.keyframes == xs.size() + 1);
  CHECK(s.bad == 1);
  CHECK(s.queries == xs.size());
  REQUIRE(queries.size() == xs.size());
  int accepted = 0;
  for (const auto& q : queries) {
    if (!q.accepted()) continue;
    ++accepted;
    INFO("query " << q.query << " candidate " << *q.candidate);
    CHECK(q.query >= 22);  // only the way back revisits
    const Eigen::Isometry3d truth = poses[static_cast<std::size_t>(*q.candidate)].inverse() *
                                    poses[static_cast<std::size_t>(q.query)];
    const Eigen::Isometry3d err = truth.inverse() * q.verification->candidate_from_query;
    CHECK(err.translation().norm() < 0.02);
  }
  CHECK(accepted >= 3);
  CHECK(s.verified == static_cast<std::size_t>(accepted));
  CHECK(s.candidates == s.verified + s.rejected);
}

TEST_CASE("LoopDetector forgets trimmed keyframes: no loop to them, their views released",
          "[loop_closure][lifelong]") {
  const Wall wall(1);
  const vs::LoopDetectorOptions o = bootstrapOptions();
  // The same walk as above, twice: once with every keyframe, once forgetting the first six (the
  // ones the way back revisits) before it comes back.
  const std::vector<double> xs = outAndBack();
  std::size_t accepted_all = 0, accepted_forgetting = 0, to_first_six = 0;
  for (const bool forgetting : {false, true}) {
    vs::LoopDetector detector(o, nullptr);
    for (std::size_t i = 0; i < xs.size(); ++i) {
      vs::LoopKeyframe k{static_cast<std::int64_t>(i), kCamera,
                         view(wall, cameraAt(xs[i], 0.02 * std::sin(static_cast<double>(i))),
                              static_cast<std::uint32_t>(100 + i))};
      for (const auto& q : detector.add(std::move(k))) {
        if (!q.accepted()) continue;
        (forgetting ? accepted_forgetting : accepted_all) += 1;
        if (forgetting) CHECK(*q.candidate >= 6);
        if (!forgetting && *q.candidate < 6) ++to_first_six;
      }
      if (forgetting && i == 21) {
        // The graph trimmed 1..5.
        std::vector<std::int64_t> all(22);
        std::iota(all.begin(), all.end(), 0);
        CHECK(detector.ids() == all);
        for (std::int64_t id = 1; id <= 5; ++id) CHECK(detector.forget(id));
        CHECK(detector.held() == 17);
        CHECK(detector.ids().front() == 0);
        CHECK(detector.ids()[1] == 6);
        CHECK(detector.forget(0));
        CHECK_FALSE(detector.forget(0));   // twice
        CHECK_FALSE(detector.forget(3));   // forgotten already
        CHECK_FALSE(detector.forget(99));  // never seen
        CHECK(detector.held() == 16);
        CHECK(detector.stats().forgotten == 6);
      }
    }
  }
  // Keyframes still waiting for the vocabulary bootstrap are forgotten too: it trains without them.
  vs::LoopDetector early(o, nullptr);
  for (std::int64_t i = 0; i < 5; ++i)
    CHECK(early.add({i, kCamera, view(wall, cameraAt(1.0 + 0.4 * i), 7)}).empty());
  CHECK(early.forget(2));
  CHECK(early.held() == 4);
  CHECK(early.stats().forgotten == 1);

  // With every keyframe the way back finds the first six; forgetting them, it finds later ones
  // (the wall is seen widely), never them.
  CHECK(accepted_all >= 3);
  CHECK(to_first_six >= 1);
  CHECK(accepted_forgetting >= 1);
}

TEST_CASE("LoopDetector refuses a keyframe whose id does not grow, keeping the one it holds",
          "[loop_closure]") {
  const Wall wall(1);
  vs::LoopDetector detector(bootstrapOptions(), nullptr);
  CHECK(detector.add({4, kCamera, view(wall, cameraAt(1.0), 7)}).empty());
  std::string why;
  CHECK(detector.add({4, kCamera, view(wall, cameraAt(1.4), 7)}, &why).empty());
  CHECK(why == "keyframe 4: id out of order; 4 was taken before");
  CHECK(detector.add({2, kCamera, view(wall, cameraAt(1.8), 7)}, &why).empty());
  CHECK(why == "keyframe 2: id out of order; 4 was taken before");
  CHECK(detector.stats().bad == 2);
  CHECK(detector.ids() == std::vector<std::int64_t>{4});
  CHECK(detector.add({5, kCamera, view(wall, cameraAt(2.2), 7)}, &why).empty());
  CHECK(why.empty());
  CHECK(detector.ids() == std::vector<std::int64_t>{4, 5});
}

TEST_CASE("LoopDetector without a vocabulary and without bootstrap finds nothing",
          "[loop_closure]") {
  vs::LoopDetectorOptions o;
  o.bootstrap_keyframes = 0;
  vs::LoopDetector detector(o, nullptr);
  const Wall wall(1);
  for (int i = 0; i < 3; ++i)
    CHECK(detector.add({i, kCamera, view(wall, cameraAt(1.0 + i), 5)}).empty());
  CHECK(detector.stats().queries == 0);
  o.bootstrap_keyframes = -1;
  CHECK_THROWS_AS(vs::LoopDetector(o, nullptr), std::invalid_argument);
}
