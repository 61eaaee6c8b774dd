#include <tessera/sim/camera_network.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <vector>

#include "polygon_margin.hpp"

using namespace tessera;
using namespace tessera::sim;

namespace {

CameraSite site(int id, double x, double y, double yaw = 0, double roll = 0, double pitch = 0) {
  CameraSite s;
  s.id = id;
  s.position = {x, y};
  s.yaw = yaw;
  s.roll = roll;
  s.pitch = pitch;
  return s;
}

}  // namespace

TEST_CASE("EnvironmentCamera: an untilted camera projects as computed by hand", "[sim][camera]") {
  sim::CameraIntrinsics in;  // h 3 m, f 320 px, 640 x 480
  const EnvironmentCamera cam(site(3, 10, 20), in);
  // u = f (x - cx) / h + W/2, v = -f (y - cy) / h + H/2 (image v points to -y for yaw 0).
  for (const Eigen::Vector2d& p :
       {Eigen::Vector2d(10, 20), Eigen::Vector2d(11.5, 19.25), Eigen::Vector2d(8.2, 21.3)}) {
    const auto px = cam.project(p);
    REQUIRE(px);
    CHECK(px->x() == Approx(320 * (p.x() - 10) / 3 + 320).margin(1e-9));
    CHECK(px->y() == Approx(-320 * (p.y() - 20) / 3 + 240).margin(1e-9));
  }
  CHECK(cam.homography()(2, 2) == Approx(1.0));
  // Footprint: 640 px * 3 m / 320 px = 6 m wide, 4.5 m deep, centred on the site.
  const auto fp = cam.footprint();
  CHECK(fp[0].x() == Approx(7.0));
  CHECK(fp[0].y() == Approx(22.25));
  CHECK(fp[2].x() == Approx(13.0));
  CHECK(fp[2].y() == Approx(17.75));
  CHECK(cam.inView({12.99, 17.76}));
  CHECK_FALSE(cam.inView({13.01, 20}));
  CHECK_FALSE(cam.inView({10, 22.26}));
}

TEST_CASE("EnvironmentCamera: yaw turns the image, tilt shifts the optical axis", "[sim][camera]") {
  sim::CameraIntrinsics in;
  // Yaw 90 deg: image u runs along +y, v along +x.
  const EnvironmentCamera turned(site(0, 0, 0, M_PI / 2), in);
  const auto px = turned.project({0, 1.5});
  REQUIRE(px);
  CHECK(px->x() == Approx(320 + 160));
  CHECK(px->y() == Approx(240).margin(1e-9));
  const auto py = turned.project({0.75, 0});
  REQUIRE(py);
  CHECK(py->x() == Approx(320).margin(1e-9));
  CHECK(py->y() == Approx(240 + 80));

  // A pure pitch of a: the image centre sees the floor h tan(a) from the site.
  for (double a : {0.05, -0.1, 0.3}) {
    const EnvironmentCamera cam(site(0, 5, 5, 0.7, 0, a), in);
    const Eigen::Vector2d centre = cam.floorPoint({320, 240});
    CHECK((centre - Eigen::Vector2d(5, 5)).norm() == Approx(3 * std::tan(std::abs(a))));
  }
}

TEST_CASE("EnvironmentCamera: project and floorPoint round-trip for tilted cameras",
          "[sim][camera]") {
  sim::CameraIntrinsics in;
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> tilt(-0.1, 0.1), off(-3, 3), yaw(-M_PI, M_PI);
  for (int i = 0; i < 50; ++i) {
    const EnvironmentCamera cam(site(i, 40, 30, yaw(rng), tilt(rng), tilt(rng)), in);
    const Eigen::Vector2d p(40 + off(rng), 30 + off(rng));
    const auto px = cam.project(p);
    REQUIRE(px);
    CHECK((cam.floorPoint(*px) - p).norm() < 1e-9);
    // The homography is a plain 3x3 map: recompute by hand.
    const Eigen::Vector3d q = cam.homography() * Eigen::Vector3d(p.x(), p.y(), 1);
    CHECK((q.head<2>() / q.z() - *px).norm() < 1e-9);
  }
  // Footprint corners are on the image border.
  const EnvironmentCamera cam(site(0, 0, 0, 0.3, 0.05, -0.04), in);
  const auto fp = cam.footprint();
  CHECK((*cam.project(fp[1]) - Eigen::Vector2d(640, 0)).norm() < 1e-6);
  CHECK((*cam.project(fp[3]) - Eigen::Vector2d(0, 480)).norm() < 1e-6);
}

TEST_CASE("EnvironmentCamera: bad intrinsics and tilts are rejected", "[sim][camera]") {
  sim::CameraIntrinsics in;
  CHECK_THROWS_AS(EnvironmentCamera(site(0, 0, 0, 0, 0.6, 0), in), std::invalid_argument);
  in.focal_px = 0;
  CHECK_THROWS_AS(EnvironmentCamera(site(0, 0, 0), in), std::invalid_argument);
  in = sim::CameraIntrinsics{};
  in.miss_probability = 1.5;
  CHECK_THROWS_AS(EnvironmentCamera(site(0, 0, 0), in), std::invalid_argument);
  in = sim::CameraIntrinsics{};
  CHECK_THROWS_AS(CameraNetwork({site(1, 0, 0), site(1, 10, 0)}, in), std::invalid_argument);
}

TEST_CASE("CameraNetwork: miss rate and pixel noise follow the configuration", "[sim][camera]") {
  sim::CameraIntrinsics in;
  in.miss_probability = 0.2;
  in.pixel_noise = 2.0;
  CameraNetwork net({site(0, 0, 0)}, in);
  std::mt19937_64 rng(3);
  const int n = 20000;
  int missed = 0, detected = 0;
  double sum = 0, sum2 = 0;
  for (int i = 0; i < n; ++i) {
    const auto frame = net.observe({0.5, -0.4}, rng);
    REQUIRE(frame.reports.size() == 1);
    const auto& r = frame.reports[0];
    if (!r.detected) {
      ++missed;
      continue;
    }
    ++detected;
    const double e = r.pixel.x() - r.true_pixel.x();
    sum += e;
    sum2 += e * e;
  }
  // Binomial: std of the count is sqrt(n p (1-p)) ~ 57; allow 4 sigma.
  CHECK(std::abs(missed - 0.2 * n) < 4 * std::sqrt(n * 0.2 * 0.8));
  CHECK(std::abs(sum / detected) < 0.1);
  CHECK(std::sqrt(sum2 / detected) == Approx(2.0).epsilon(0.05));

  in.miss_probability = 0;
  in.pixel_noise = 0;
  CameraNetwork exact({site(0, 0, 0)}, in);
  const auto f = exact.observe({0.5, -0.4}, rng);
  REQUIRE(f.reports.size() == 1);
  CHECK(f.reports[0].detected);
  CHECK(f.reports[0].pixel == f.reports[0].true_pixel);
}

TEST_CASE("CameraNetwork: one enter and one leave event on a straight pass under a camera",
          "[sim][camera]") {
  sim::CameraIntrinsics in;
  in.miss_probability = 0.3;  // misses must not cause spurious leave events
  CameraNetwork net({site(5, 10, 0), site(6, 30, 0)}, in);
  std::mt19937_64 rng(11);
  std::vector<std::pair<double, CameraTransition>> events;
  int reports_cam5 = 0;
  for (int k = 0; k <= 400; ++k) {  // x from 0 to 20 in 5 cm steps, y = 0
    const double x = 0.05 * k;
    const auto frame = net.observe({x, 0}, rng);
    for (const auto& t : frame.transitions) events.push_back({x, t});
    for (const auto& r : frame.reports) {
      CHECK(r.camera_id == 5);
      ++reports_cam5;
    }
  }
  REQUIRE(events.size() == 2);
  CHECK(events[0].second.camera_id == 5);
  CHECK(events[0].second.entered);
  CHECK(events[0].first == Approx(7.0));  // footprint x in [7, 13)
  CHECK(events[1].second.camera_id == 5);
  CHECK_FALSE(events[1].second.entered);
  CHECK(events[1].first == Approx(13.0));
  CHECK(reports_cam5 == 120);  // x = 7.00 .. 12.95

  // After reset() a marker still in view is reported as a fresh entry.
  net.observe({10, 0}, rng);
  net.reset();
  const auto again = net.observe({10, 0}, rng);
  REQUIRE(again.transitions.size() == 1);
  CHECK(again.transitions[0].entered);
}

namespace footprint_polygon_test {

double signedArea(const std::vector<Eigen::Vector2d>& poly) {
  double a = 0;
  for (std::size_t i = 0; i < poly.size(); ++i) {
    const auto& p = poly[i];
    const auto& q = poly[(i + 1) % poly.size()];
    a += p.x() * q.y() - q.x() * p.y();
  }
  return 0.5 * a;
}

using tessera::test::insideMargin;

// inView agrees with the polygon on random floor points around the site (those within 1e-6 m of
// its border are not judged).
void requireAgrees(const EnvironmentCamera& cam, const std::vector<Eigen::Vector2d>& poly,
                   double box) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> d(-box, box);
  int in = 0, out = 0;
  for (int i = 0; i < 4000; ++i) {
    const Eigen::Vector2d p = cam.site().position + Eigen::Vector2d(d(rng), d(rng));
    const double m = insideMargin(poly, p);
    if (std::abs(m) < 1e-6) continue;
    CAPTURE(p.x(), p.y(), m);
    REQUIRE(cam.inView(p) == (m > 0));
    ++(m > 0 ? in : out);
  }
  CHECK(in > 50);
  CHECK(out > 50);
}

}  // namespace footprint_polygon_test

TEST_CASE("EnvironmentCamera: the footprint polygon is the image border on the floor",
          "[sim][camera][footprint]") {
  using footprint_polygon_test::insideMargin;
  using footprint_polygon_test::requireAgrees;
  using footprint_polygon_test::signedArea;
  sim::CameraIntrinsics in;
  SECTION("untilted: the four corners, counter-clockwise") {
    const EnvironmentCamera cam(site(3, 10, 20), in);
    const auto poly = cam.footprintPolygon(30);
    REQUIRE(poly.size() == 4);
    CHECK(signedArea(poly) == Approx(6.0 * 4.5));
    for (const auto& corner : cam.footprint()) {
      bool found = false;
      for (const auto& p : poly) found = found || (p - corner).norm() < 1e-9;
      CHECK(found);
    }
    CHECK(insideMargin(poly, cam.site().position) > 2.0);
    requireAgrees(cam, poly, 5);
  }
  SECTION("yawed and tilted: a convex quadrilateral holding the site") {
    for (const CameraSite& s : {site(0, 1, 2, 0.7, 0.3, -0.2), site(1, -4, 3, -2.5, -0.45, 0.45),
                                site(2, 0, 0, M_PI, 0.1, 0.4)}) {
      CAPTURE(s.id);
      const EnvironmentCamera cam(s, in);
      const auto poly = cam.footprintPolygon(30);
      REQUIRE(poly.size() >= 4);
      CHECK(signedArea(poly) > 0);
      CHECK(insideMargin(poly, s.position) > 0);
      requireAgrees(cam, poly, 12);
    }
  }
  SECTION("a wide view tilted past the horizon is cut at max_distance") {
    sim::CameraIntrinsics wide = in;
    wide.focal_px = 120;  // 2 x 69 deg across the width
    const EnvironmentCamera cam(site(4, 5, 5, 0.3, 0.45, 0.45), wide);
    // Some image corner's ray misses the floor: its floor point lies behind the camera.
    bool past_horizon = false;
    for (const auto& corner : cam.footprint()) past_horizon = past_horizon || !cam.project(corner);
    CHECK(past_horizon);
    const auto poly = cam.footprintPolygon(20);
    REQUIRE(poly.size() >= 3);
    CHECK(signedArea(poly) > 0);
    for (const auto& p : poly) {
      REQUIRE(p.allFinite());
      CHECK((p - cam.site().position).lpNorm<Eigen::Infinity>() <= 20 + 1e-9);
    }
    CHECK(insideMargin(poly, cam.site().position) > 0);
    requireAgrees(cam, poly, 19.9);
  }
  CHECK_THROWS_AS(EnvironmentCamera(site(0, 0, 0), in).footprintPolygon(0), std::invalid_argument);
}
