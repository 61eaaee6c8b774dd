// sick_lms against the emulated LMS200 on a pseudo-terminal, in a real runtime on the wall
// clock: found at its power-up 9600 baud and switched to 500 kBd, every scan genuine; unplugged
// (it comes back at 9600) and found again; refused options.
#include <tessera/drivers/emulator_host.hpp>
#include <tessera/drivers/sick_lms_device.hpp>
#include <tessera/drivers/sick_lms_driver_actor.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/runtime.hpp>

#include <catch2/catch.hpp>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <mutex>
#include <thread>

namespace sick_lms_driver_actor_test {

using namespace tessera;
using namespace tessera::drivers;

/// Sweep k of a room: beam 1 says k, the others are fixed, beam 0 has no echo.
std::vector<std::uint32_t> sweep(int angle, int res, int k) {
  std::vector<std::uint32_t> mm(static_cast<std::size_t>(angle * 100 / res + 1));
  for (std::size_t i = 0; i < mm.size(); ++i)
    mm[i] = static_cast<std::uint32_t>(400 + i * 13 % 6000);
  mm[0] = 0;
  mm[1] = static_cast<std::uint32_t>(1000 + k % 5000);
  return mm;
}

bool genuine(const std::vector<float>& r) {
  if (r.size() != 181 || !std::isinf(r[0]) || !std::isfinite(r[1])) return false;
  const auto mm = sweep(180, 100, static_cast<int>(std::lround(r[1] * 1000)) - 1000);
  for (std::size_t i = 1; i < r.size(); ++i)
    if (r[i] != static_cast<float>(mm[i] * 1e-3)) return false;
  return true;
}

class Catcher final : public Actor {
 public:
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::LaserScan>("scan", MailboxPolicy::reliable(10000),
                                  [this](const Message<msg::LaserScan>& m) {
                                    const auto r = view<float>(m->getRanges());
                                    const bool ok = genuine({r.begin(), r.end()});
                                    std::lock_guard lock(mutex);
                                    ++count;
                                    if (!ok) ++bad;
                                  });
  }
  std::size_t seen() const {
    std::lock_guard lock(mutex);
    return count;
  }
  mutable std::mutex mutex;
  std::size_t count = 0, bad = 0;
};

struct Lms {
  explicit Lms(const std::string& link)
      : device([this](int a, int r) { return sweep(a, r, k++); }),
        host(EmulatedDevice{[this](std::string_view b, std::int64_t t) { device.receive(b, t); },
                            [this](std::int64_t t) { return device.poll(t); },
                            [this] { return device.nextDue(); },
                            [this](std::int64_t t) { device.restart(t); },
                            [this] { return device.baud(); }},
             EmulatorHostOptions{link, -1, 9600}) {}
  int k = 0;
  SickLmsDevice device;
  EmulatorHost host;
};

TEST_CASE("sick_lms finds an LMS200 at 9600 baud, switches it to 500 kBd and streams 75 Hz",
          "[drivers][sick_lms]") {
  const auto dir = std::filesystem::temp_directory_path() / "tessera_sick_lms_test";
  std::filesystem::create_directories(dir);
  Lms lms((dir / "lms").string());
  SickLmsDriverOptions o;
  o.device = lms.host.devicePath();
  o.baud = 500000;
  o.retry_initial_s = 0.05;
  o.client.reply_timeout_s = 0.3;
  RuntimeOptions ro;
  ro.clock = ClockKind::kWall;
  ro.threads = 2;
  ro.show_progress = false;
  Runtime rt(ro);
  rt.add("laser", std::make_unique<SickLmsDriverActor>(o));
  auto& c = static_cast<Catcher&>(rt.add("catcher", std::make_unique<Catcher>()));
  RunReport report;
  std::thread runner([&] { report = rt.run(); });
  const auto waitFor = [&c](std::size_t n, double seconds) {
    for (int i = 0; i < seconds * 50 && c.seen() < n; ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
  };
  waitFor(1, 10);
  const std::size_t first = c.seen();
  const auto t0 = std::chrono::steady_clock::now();
  std::this_thread::sleep_for(std::chrono::milliseconds(1000));
  const double rate = (c.seen() - first) /
                      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // Unplugged: it comes back at 9600, and the driver finds it again.
  const std::size_t before = c.seen();
  lms.host.unplug(0.3);
  waitFor(before + 20, 15);
  const std::size_t after = c.seen();
  rt.requestStop();
  runner.join();
  CHECK(first >= 1);
  CHECK(rate > 60);  // 75 Hz, less the scheduling of a busy machine
  CHECK(after >= before + 20);
  CHECK(c.bad == 0);
  CHECK(lms.host.withDevice([&] { return lms.device.millimetres(); }));
  const auto& s = report.actors.at(0).summary;
  CHECK(std::get<std::int64_t>(s.at("baud")) == 500000);
  CHECK(std::get<std::int64_t>(s.at("reconnects")) >= 2);
  CHECK(std::get<std::int64_t>(s.at("sessions")) >= 2);
}

TEST_CASE("sick_lms refuses options the LMS does not have", "[drivers][sick_lms]") {
  SickLmsDriverOptions o;
  o.baud = 115200;
  CHECK_THROWS_WITH(SickLmsDriverActor(o), Catch::Contains("'baud'"));
  o = {};
  o.client.angle_deg = 270;
  CHECK_THROWS_WITH(SickLmsDriverActor(o), Catch::Contains("'client'"));
  o = {};
  o.mount = {1, 2};
  CHECK_THROWS_WITH(SickLmsDriverActor(o), Catch::Contains("'mount'"));
}

}  // namespace sick_lms_driver_actor_test
