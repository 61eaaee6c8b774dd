#include <tessera/sim/world.hpp>

#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <random>
#include <string>

using tessera::sim::Route;
using tessera::sim::World;

namespace {

// A fresh scratch folder per test case, removed afterwards.
struct TempDir {
  std::filesystem::path path;
  TempDir() {
    std::random_device rd;
    path = std::filesystem::temp_directory_path() /
           ("tessera_world_test_" + std::to_string(rd()) + std::to_string(rd()));
    std::filesystem::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
  std::string file(const std::string& name) const { return (path / name).string(); }
};

// Binary PGM (P5), written by hand so the test needs no image library.
void writePgm(const std::string& path, int w, int h, const std::vector<unsigned char>& px) {
  std::ofstream f(path, std::ios::binary);
  f << "P5\n" << w << " " << h << "\n255\n";
  f.write(reinterpret_cast<const char*>(px.data()), static_cast<std::streamsize>(px.size()));
}

std::string messageOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("World: construction checks its arguments", "[sim][world]") {
  CHECK_THROWS_AS(World(0, 10, 0.1), std::invalid_argument);
  CHECK_THROWS_AS(World(10, -1, 0.1), std::invalid_argument);
  CHECK_THROWS_AS(World(10, 10, 0.0), std::invalid_argument);
  CHECK_THROWS_AS(World(10, 10, -0.05), std::invalid_argument);
  World w(10, 5, 0.1);
  CHECK(w.width() == 10);
  CHECK(w.height() == 5);
  CHECK(w.widthMeters() == Approx(1.0));
  CHECK(w.heightMeters() == Approx(0.5));
  CHECK_FALSE(w.wall(3, 3));
  CHECK_FALSE(w.wall(-1, 0));      // outside is open space for rays...
  CHECK(w.blocked({-0.01, 0.2}));  // ...but not somewhere a robot can be
}

TEST_CASE("World: cells, points and drawing", "[sim][world]") {
  World w(100, 80, 0.05);
  CHECK(w.cellOf({0.0, 0.0}) == Eigen::Vector2i(0, 0));
  CHECK(w.cellOf({0.049, 0.051}) == Eigen::Vector2i(0, 1));
  CHECK(w.cellOf({-0.01, 0.0}) == Eigen::Vector2i(-1, 0));

  // A rectangle covers exactly the cells whose centres lie inside it.
  w.fillRect(1.0, 2.0, 1.2, 2.1);
  int count = 0;
  for (int r = 0; r < w.height(); ++r)
    for (int c = 0; c < w.width(); ++c) count += w.wall(c, r);
  CHECK(count == 4 * 2);
  CHECK(w.wall(20, 40));
  CHECK(w.wall(23, 41));
  CHECK_FALSE(w.wall(24, 41));
  CHECK_FALSE(w.wall(20, 42));
  CHECK(w.blocked({1.01, 2.01}));

  w.fillRect(1.0, 2.0, 1.2, 2.1, false);  // erase
  w.fillDisc(2.5, 2.0, 0.5);
  CHECK(w.wall(50, 40));
  CHECK(w.blocked({2.5 + 0.45, 2.0}));
  CHECK_FALSE(w.blocked({2.5 + 0.55, 2.0}));
  CHECK_FALSE(w.blocked({2.5 + 0.36, 2.0 + 0.36}));  // 0.51 m from the centre, diagonally
}

TEST_CASE("World: box has one-cell walls and analytic clearance", "[sim][world]") {
  World b = World::box(10.0, 8.0, 0.1);
  REQUIRE(b.width() == 100);
  REQUIRE(b.height() == 80);
  for (int c = 0; c < b.width(); ++c) {
    CHECK(b.wall(c, 0));
    CHECK(b.wall(c, 79));
    CHECK_FALSE(b.wall(c == 0 || c == 99 ? 50 : c, 1));
  }
  for (int r = 0; r < b.height(); ++r) {
    CHECK(b.wall(0, r));
    CHECK(b.wall(99, r));
  }
  // The inner faces are at 0.1 and 9.9 (x), 0.1 and 7.9 (y).
  CHECK(b.clearance({5.0, 4.0}, 10.0) == Approx(3.9));
  CHECK(b.clearance({0.5, 4.0}, 10.0) == Approx(0.4));
  CHECK(b.clearance({5.0, 4.0}, 1.0) == Approx(1.0));  // capped
  CHECK(b.clearance({0.05, 4.0}, 1.0) == 0.0);         // inside a wall
  CHECK(b.clearance({0.4, 0.5}, 10.0) == Approx(0.3));

  World thick = World::box(4.0, 4.0, 0.1, 3);
  CHECK(thick.wall(2, 20));
  CHECK_FALSE(thick.wall(3, 20));
  CHECK_THROWS_AS(World::box(0.2, 5.0, 0.1, 1), std::invalid_argument);
  CHECK_THROWS_AS(World::box(5.0, 5.0, 0.0), std::invalid_argument);
}

TEST_CASE("World: the built-in office", "[sim][world]") {
  const World w = World::builtinOffice();
  CHECK(w.name() == "builtin:office");
  CHECK(w.resolution() == 0.05);
  CHECK(w.widthMeters() == Approx(40.0));
  CHECK(w.heightMeters() == Approx(30.0));

  // Closed outside: every border cell is a wall.
  for (int c = 0; c < w.width(); ++c) CHECK((w.wall(c, 0) && w.wall(c, w.height() - 1)));
  for (int r = 0; r < w.height(); ++r) CHECK((w.wall(0, r) && w.wall(w.width() - 1, r)));

  // Some structure: a good share of walls, but mostly free.
  int walls = 0;
  for (int r = 0; r < w.height(); ++r)
    for (int c = 0; c < w.width(); ++c) walls += w.wall(c, r);
  const double wall_share = static_cast<double>(walls) / (w.width() * w.height());
  CHECK(wall_share > 0.03);
  CHECK(wall_share < 0.25);

  // Corridor centres and door gaps are open; a pillar stands in the bottom corridor.
  CHECK_FALSE(w.blocked({20.0, 7.5}));
  CHECK_FALSE(w.blocked({21.0, 6.0}));  // door of the middle bottom room
  CHECK(w.blocked({19.0, 6.0}));        // wall next to it
  CHECK_FALSE(w.blocked({9.0, 15.0}));  // west entrance of the cross corridor
  CHECK(w.blocked({15.0, 8.5}));        // pillar

  CHECK(World::builtin("office") == w);
}

TEST_CASE("World: the default route of the office is a clear closed loop of 150-250 m",
          "[sim][world]") {
  const World w = World::builtinOffice();
  const Route& route = w.defaultRoute();
  REQUIRE(route.size() >= 10);
  const double length = tessera::sim::routeLength(route);
  CHECK(length > 150.0);
  CHECK(length < 250.0);
  CHECK((route.front() - route.back()).norm() < 0.5);  // returns to its start

  for (std::size_t i = 0; i < route.size(); ++i) {
    INFO("waypoint " << i << " at (" << route[i].x() << ", " << route[i].y() << ")");
    CHECK_FALSE(w.blocked(route[i]));
  }
  // Sampled every 2 cm, every leg stays at least 0.35 m from any wall or obstacle.
  for (std::size_t i = 1; i < route.size(); ++i) {
    const double clear = tessera::sim::segmentClearance(w, route[i - 1], route[i], 0.02, 1.0);
    INFO("leg " << i - 1 << " -> " << i << " from (" << route[i - 1].x() << ", " << route[i - 1].y()
                << ") to (" << route[i].x() << ", " << route[i].y() << "): clearance " << clear);
    CHECK(clear >= 0.35);
  }
}

TEST_CASE("World: unknown built-in names list the known ones", "[sim][world]") {
  const std::string msg = messageOf([] { (void)World::builtin("warehouse"); });
  CHECK(msg.find("warehouse") != std::string::npos);
  CHECK(msg.find("office") != std::string::npos);
  CHECK_THROWS_AS(World::builtin("warehouse"), std::runtime_error);
}

TEST_CASE("World: loading images flips rows and thresholds at 128", "[sim][world]") {
  TempDir dir;
  const std::string path = dir.file("tiny.pgm");
  // 4 x 3 image; image row 0 is the top, so the dark pixel (0,0) is world cell (0, 2).
  writePgm(path, 4, 3,
           {0, 255, 255, 255,    //
            255, 127, 128, 255,  //
            255, 255, 255, 10});
  const World w = World::fromImage(path, 0.1);
  REQUIRE(w.width() == 4);
  REQUIRE(w.height() == 3);
  CHECK(w.resolution() == 0.1);
  CHECK(w.name() == path);
  CHECK(w.wall(0, 2));
  CHECK(w.wall(1, 1));        // 127 < 128
  CHECK_FALSE(w.wall(2, 1));  // 128 is free
  CHECK(w.wall(3, 0));
  CHECK_FALSE(w.wall(0, 0));
  CHECK(w.defaultRoute().empty());
}

TEST_CASE("World: saveImage and fromImage round-trip", "[sim][world]") {
  TempDir dir;
  const World office = World::builtinOffice();
  for (const char* name : {"office.pgm", "office.png"}) {
    const std::string path = dir.file(name);
    office.saveImage(path);
    CHECK(World::fromImage(path, 0.05) == office);
  }
}

TEST_CASE("World: bad image files give errors naming the file and the problem", "[sim][world]") {
  TempDir dir;
  const std::string missing = dir.file("nope.pgm");
  std::string msg = messageOf([&] { (void)World::fromImage(missing, 0.05); });
  CHECK(msg.find(missing) != std::string::npos);
  CHECK(msg.find("not found") != std::string::npos);

  const std::string text = dir.file("notes.png");
  std::ofstream(text) << "this is not an image\n";
  msg = messageOf([&] { (void)World::fromImage(text, 0.05); });
  CHECK(msg.find(text) != std::string::npos);
  CHECK(msg.find("not a readable image") != std::string::npos);

  const std::string empty = dir.file("empty.pgm");
  std::ofstream(empty).close();
  msg = messageOf([&] { (void)World::fromImage(empty, 0.05); });
  CHECK(msg.find(empty) != std::string::npos);
  CHECK(msg.find("empty") != std::string::npos);

  msg = messageOf([&] { (void)World::fromImage(dir.path.string(), 0.05); });
  CHECK(msg.find("directory") != std::string::npos);

  const std::string good = dir.file("good.pgm");
  writePgm(good, 2, 2, {0, 255, 255, 0});
  CHECK_THROWS_AS(World::fromImage(good, 0.0), std::invalid_argument);
  CHECK_THROWS_AS(World::fromImage(good, -1.0), std::invalid_argument);
  CHECK_THROWS_AS(World::fromImage(missing, 0.05), std::runtime_error);
}

TEST_CASE("World: routeLength and segmentClearance", "[sim][world]") {
  CHECK(tessera::sim::routeLength({}) == 0.0);
  CHECK(tessera::sim::routeLength({{0, 0}, {3, 4}, {3, 0}}) == Approx(9.0));
  const World b = World::box(10.0, 8.0, 0.1);
  // A leg parallel to the bottom wall at y = 1 stays 0.9 m from it, and its ends 0.9 m from the
  // side walls.
  CHECK(tessera::sim::segmentClearance(b, {1.0, 1.0}, {9.0, 1.0}, 0.05, 5.0) == Approx(0.9));
  CHECK(tessera::sim::segmentClearance(b, {5.0, 4.0}, {9.95, 4.0}, 0.05, 5.0) == 0.0);
  CHECK_THROWS_AS(tessera::sim::segmentClearance(b, {1, 1}, {2, 2}, 0.0, 1.0),
                  std::invalid_argument);
}

TEST_CASE("World: checkRoute names the bad waypoint or leg", "[sim][world]") {
  const World office = World::builtinOffice();
  CHECK_NOTHROW(tessera::sim::checkRoute(office, office.defaultRoute()));
  CHECK_NOTHROW(tessera::sim::checkRoute(office, office.defaultRoute(), true));

  std::string msg = messageOf([&] { tessera::sim::checkRoute(office, {}); });
  CHECK(msg.find("at least two waypoints") != std::string::npos);
  msg = messageOf([&] { tessera::sim::checkRoute(office, {{7.5, 7.5}}); });
  CHECK(msg.find("got 1") != std::string::npos);

  // Waypoint 2 sits on the pillar at (15, 8.5).
  msg = messageOf([&] { tessera::sim::checkRoute(office, {{7.5, 7.5}, {12, 7.5}, {15, 8.5}}); });
  CHECK(msg.find("waypoint 2 at (15, 8.5) is inside a wall") != std::string::npos);
  msg = messageOf([&] { tessera::sim::checkRoute(office, {{7.5, 7.5}, {45, 7.5}}); });
  CHECK(msg.find("waypoint 1 at (45, 7.5) is outside") != std::string::npos);

  // Both ends free, but the leg goes through the wall at y = 6.
  msg = messageOf([&] { tessera::sim::checkRoute(office, {{12, 7.5}, {12, 3}}); });
  CHECK(msg.find("leg from waypoint 0 (12, 7.5) to waypoint 1 (12, 3) crosses a wall") !=
        std::string::npos);
  // Open route driven in laps: the closing leg is checked too.
  CHECK_NOTHROW(tessera::sim::checkRoute(office, {{20, 7.5}, {21, 7.5}, {21, 3}}, false));
  CHECK_THROWS_AS(tessera::sim::checkRoute(office, {{20, 7.5}, {21, 7.5}, {21, 3}}, true),
                  std::invalid_argument);
}

TEST_CASE("World::fromSpec reads a world option: builtin names or image paths", "[sim][world]") {
  const World room = World::fromSpec("builtin:room", 0.05);
  CHECK(room.width() == World::builtin("room").width());
  CHECK(room.name() == World::builtin("room").name());
  CHECK_THROWS_WITH(World::fromSpec("builtin:nowhere", 0.05),
                    Catch::Contains("unknown built-in world 'nowhere'"));
  CHECK_THROWS_AS(World::fromSpec("/no/such/map.pgm", 0.05), std::runtime_error);
}
