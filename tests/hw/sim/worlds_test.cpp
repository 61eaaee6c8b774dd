// The scenario worlds of seeds 000, 001 and 004, and wallSegments().
#include <tessera/sim/camera_network.hpp>
#include <tessera/sim/robot.hpp>
#include <tessera/sim/world.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <set>

using namespace tessera;
using namespace tessera::sim;

TEST_CASE("wallSegments: a box has four inner faces, free space on their left", "[sim][worlds]") {
  const World box = World::box(4, 3, 0.1);
  const auto faces = wallSegments(box);
  REQUIRE(faces.size() == 4);
  double total = 0;
  for (const auto& f : faces) {
    total += f.length();
    // The point just left of the face's midpoint is free, just right is a wall.
    const Eigen::Vector2d mid = 0.5 * (f.a + f.b), dir = (f.b - f.a).normalized();
    const Eigen::Vector2d left(-dir.y(), dir.x());
    CHECK_FALSE(box.blocked(mid + 0.05 * left));
    CHECK(box.blocked(mid - 0.05 * left));
  }
  CHECK(total == Approx(2 * (3.8 + 2.8)));
  // A block in open space: four faces; the map border is no face (outside is not free space).
  World open(10, 10, 1.0);
  open.fillRect(3, 3, 5, 5);
  CHECK(wallSegments(open).size() == 4);
  CHECK(wallSegments(open, 2.5).empty());
}

TEST_CASE("World: the seed 000 camera floor", "[sim][worlds]") {
  const World w = World::builtin("camera_floor");
  CHECK(w.name() == "builtin:camera_floor");
  CHECK(w.widthMeters() == Approx(85));
  CHECK(w.heightMeters() == Approx(63));
  REQUIRE(w.cameraSites().size() == 7);

  const Route& route = w.defaultRoute();
  REQUIRE_NOTHROW(checkRoute(w, route));
  const double length = routeLength(route);
  INFO("route length " << length << " m");
  CHECK(length > 1400);
  CHECK(length < 1600);
  // Corridors are 3 m wide: the route keeps at least 0.45 m from every wall.
  double worst = 10;
  for (std::size_t i = 1; i < route.size(); ++i)
    worst = std::min(worst, segmentClearance(w, route[i - 1], route[i], 0.05, 2.0));
  CHECK(worst >= 0.45);

  // Every camera's footprint is entered by the route, and more than once (revisits).
  CameraNetwork net(w.cameraSites(), sim::CameraIntrinsics{});
  std::vector<int> entries(7, 0);
  std::mt19937_64 rng(1);
  for (std::size_t i = 1; i < route.size(); ++i) {
    const double leg = (route[i] - route[i - 1]).norm();
    const int n = static_cast<int>(leg / 0.1) + 1;
    for (int k = 0; k < n; ++k) {
      const auto frame = net.observe(route[i - 1] + (route[i] - route[i - 1]) * k / n, rng);
      for (const auto& t : frame.transitions)
        if (t.entered) ++entries[static_cast<std::size_t>(t.camera_id)];
    }
  }
  for (int i = 0; i < 7; ++i) {
    INFO("camera " << i);
    CHECK(entries[static_cast<std::size_t>(i)] >= 2);
  }
  // Footprints of ~6 m x 4.5 m do not overlap (each entry starts a new local map).
  for (std::size_t a = 0; a < 7; ++a)
    for (std::size_t b = a + 1; b < 7; ++b)
      CHECK((w.cameraSites()[a].position - w.cameraSites()[b].position).norm() > 20);
}

TEST_CASE("World: the seed 001 room has straight walls and a 15 m route", "[sim][worlds]") {
  const World w = World::builtin("room");
  CHECK(w.widthMeters() == Approx(10.4));
  CHECK(w.heightMeters() == Approx(8.4));
  REQUIRE_NOTHROW(checkRoute(w, w.defaultRoute()));
  CHECK(routeLength(w.defaultRoute()) == Approx(15).margin(0.5));
  const auto all = wallSegments(w);
  const auto listed = wallSegments(w, 0.3);
  CHECK(all.size() == 24);
  CHECK(listed.size() == 23);
  for (const auto& s : all) CHECK((s.a.x() == s.b.x() || s.a.y() == s.b.y()));
  CHECK(w.cameraSites().empty());
  CHECK(w.landmarks().empty());
}

TEST_CASE("World: the seed 004 landmark world", "[sim][worlds]") {
  const World w = World::builtin("landmarks");
  CHECK(w.widthMeters() == Approx(100));
  CHECK(w.heightMeters() == Approx(90));
  CHECK(wallSegments(w).empty());
  REQUIRE(w.defaultRoute().size() == 14);
  REQUIRE_NOTHROW(checkRoute(w, w.defaultRoute()));
  REQUIRE(w.landmarks().size() == 27);
  std::set<int> ids;
  for (const auto& lm : w.landmarks()) {
    ids.insert(lm.id);
    CHECK_FALSE(w.blocked(lm.position));
  }
  CHECK(ids.size() == 27);
  // Landmarks lie beside the route, not on it.
  for (const auto& lm : w.landmarks()) {
    double nearest = 1e9;
    const Route& r = w.defaultRoute();
    for (std::size_t i = 1; i < r.size(); ++i) {
      const Eigen::Vector2d d = r[i] - r[i - 1];
      const double t = std::clamp((lm.position - r[i - 1]).dot(d) / d.squaredNorm(), 0.0, 1.0);
      nearest = std::min(nearest, (lm.position - (r[i - 1] + t * d)).norm());
    }
    INFO("landmark " << lm.id);
    CHECK(nearest > 2.0);
    CHECK(nearest < 25.0);
  }
  // The built-in names list the new worlds.
  const auto names = World::builtinNames();
  for (const char* n : {"office", "camera_floor", "room", "landmarks"})
    CHECK(std::find(names.begin(), names.end(), n) != names.end());
}
