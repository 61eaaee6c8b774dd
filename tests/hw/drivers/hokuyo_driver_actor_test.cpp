// hokuyo_scip against the emulated URG-04LX on a pseudo-terminal and on TCP, in a real runtime
// on the wall clock: streaming, garbage and bad checksums, a silent device, an unplugged one, a
// wrong baud rate and a missing device. Every published scan must be one the device measured.
#include <tessera/drivers/emulator_host.hpp>
#include <tessera/drivers/hokuyo_driver_actor.hpp>
#include <tessera/drivers/scip_device.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/runtime.hpp>

#include <catch2/catch.hpp>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <mutex>
#include <thread>

namespace hokuyo_driver_actor_test {

using namespace tessera;
using namespace tessera::drivers;

/// Scan k of the emulated device; step 44's reading tells which k it is.
EmulatedScan numberedScan(int k) {
  EmulatedScan s;
  for (int step = 44; step <= 725; ++step)
    s.ranges_mm.push_back(static_cast<std::uint32_t>(300 + (step * 11 + k * 17) % 4000));
  s.ranges_mm[0] = static_cast<std::uint32_t>(1000 + k);
  s.ranges_mm[1] = 0;
  return s;
}

/// Which numberedScan the ranges are; -1 when none matches exactly.
int scanNumber(const std::vector<float>& ranges) {
  if (ranges.size() != 682 || !std::isfinite(ranges[0])) return -1;
  const int k = static_cast<int>(std::lround(ranges[0] * 1000)) - 1000;
  const auto src = numberedScan(k);
  if (!std::isinf(ranges[1])) return -1;
  for (std::size_t i = 2; i < ranges.size(); ++i)
    if (ranges[i] != static_cast<float>(static_cast<double>(src.ranges_mm[i]) * 1e-3)) return -1;
  return k;
}

class ScanCatcher final : public Actor {
 public:
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::LaserScan>("scan", MailboxPolicy::reliable(10000),
                                  [this](const Message<msg::LaserScan>& m) {
                                    const auto ranges = view<float>(m->getRanges());
                                    const std::vector<float> r(ranges.begin(), ranges.end());
                                    std::lock_guard lock(mutex);
                                    numbers.push_back(scanNumber(r));
                                    stamps.push_back(m->getHeader().getStampNs());
                                  });
  }
  std::size_t count() const {
    std::lock_guard lock(mutex);
    return numbers.size();
  }
  mutable std::mutex mutex;
  std::vector<int> numbers;
  std::vector<Nanos> stamps;
};

/// The emulated URG-04LX with scans 0, 1, 2, …
struct Device {
  explicit Device(EmulatorHostOptions o = {})
      : device(ScipDevice::urg04lx(),
               [this]() -> std::optional<EmulatedScan> { return numberedScan(next++); }),
        host(EmulatedDevice{[this](std::string_view b, std::int64_t t) { device.receive(b, t); },
                            [this](std::int64_t t) { return device.poll(t); },
                            [this] { return device.nextDue(); },
                            [this](std::int64_t t) { device.restart(t); },
                            {}},
             o) {}
  int next = 0;
  ScipDevice device;
  EmulatorHost host;
};

/// What the catcher got, kept after its runtime is gone.
struct Caught {
  std::vector<int> numbers;
  std::vector<Nanos> stamps;
  std::size_t count() const { return numbers.size(); }
};

/// Runs the driver until `done` or `timeout_s`, then stops the run; returns the report and, in
/// `caught`, the scans.
RunReport runDriver(HokuyoDriverOptions o, Caught& caught,
                    const std::function<bool(const ScanCatcher&)>& done, double timeout_s,
                    const std::function<void(double, const ScanCatcher&)>& during = {}) {
  ScanCatcher* catcher = nullptr;
  RuntimeOptions ro;
  ro.clock = ClockKind::kWall;
  ro.threads = 2;
  ro.show_progress = false;
  Runtime rt(ro);
  rt.add("laser", std::make_unique<HokuyoDriverActor>(std::move(o)));
  catcher = &static_cast<ScanCatcher&>(rt.add("catcher", std::make_unique<ScanCatcher>()));
  RunReport report;
  std::thread runner([&] { report = rt.run(); });
  const auto t0 = std::chrono::steady_clock::now();
  for (;;) {
    const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (t > timeout_s || done(*catcher)) break;
    if (during) during(t, *catcher);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  rt.requestStop();
  runner.join();
  caught.numbers = catcher->numbers;
  caught.stamps = catcher->stamps;
  return report;
}

const Summary& driverSummary(const RunReport& r) {
  return r.actors.at(0).summary;
}
std::int64_t figure(const RunReport& r, const std::string& key) {
  return std::get<std::int64_t>(driverSummary(r).at(key));
}

void checkAllGenuineInOrder(const Caught& c) {
  for (std::size_t k = 0; k < c.numbers.size(); ++k) {
    INFO("scan " << k);
    CHECK(c.numbers[k] >= 0);  // nothing corrupt or invented
    if (k > 0) CHECK(c.numbers[k] > c.numbers[k - 1]);
    if (k > 0) CHECK(c.stamps[k] > c.stamps[k - 1]);
  }
}

TEST_CASE("hokuyo_scip streams an emulated URG-04LX over a pseudo-terminal",
          "[drivers][hokuyo_scip]") {
  Device dev;
  HokuyoDriverOptions o;
  o.device = dev.host.devicePath();
  Caught c;
  const auto report = runDriver(
      o, c, [](const ScanCatcher& s) { return s.count() >= 15; }, 10);
  REQUIRE(c.count() >= 15);
  checkAllGenuineInOrder(c);
  CHECK(c.numbers.front() <= 1);  // from the first scans on
  // The sensor's 100 ms, not the host's, once the clock offset has seen a fast transfer.
  for (std::size_t k = 4; k < c.stamps.size(); ++k)
    CHECK(nanosToSeconds(c.stamps[k] - c.stamps[k - 1]) ==
          Approx(0.1 * (c.numbers[k] - c.numbers[k - 1])).margin(0.003));
  CHECK(figure(report, "sessions") == 1);
  CHECK(figure(report, "reconnects") == 0);
  CHECK(std::get<std::string>(driverSummary(report).at("model")) ==
        "URG-04LX(Hokuyo Automatic Co.,Ltd.)");
}

TEST_CASE("hokuyo_scip streams over TCP", "[drivers][hokuyo_scip]") {
  EmulatorHostOptions ho;
  ho.tcp_port = 0;
  Device dev(ho);
  HokuyoDriverOptions o;
  o.device = dev.host.devicePath();
  Caught c;
  runDriver(
      o, c, [](const ScanCatcher& s) { return s.count() >= 10; }, 10);
  REQUIRE(c.count() >= 10);
  checkAllGenuineInOrder(c);
}

TEST_CASE("hokuyo_scip drops garbage and corrupt replies and publishes only genuine scans",
          "[drivers][hokuyo_scip]") {
  Device dev;
  dev.host.withDevice([&] {
    dev.device.faults().garbage_probability = 0.3;
    dev.device.faults().corrupt_probability = 0.3;
  });
  HokuyoDriverOptions o;
  o.device = dev.host.devicePath();
  o.retry_initial_s = 0.05;
  Caught c;
  const auto report = runDriver(
      o, c, [](const ScanCatcher& s) { return s.count() >= 20; }, 20);
  REQUIRE(c.count() >= 20);
  checkAllGenuineInOrder(c);
  CHECK(figure(report, "bad_replies") > 0);
  CHECK(figure(report, "garbage_bytes") > 0);
}

TEST_CASE("hokuyo_scip reconnects to a device that went silent or was unplugged",
          "[drivers][hokuyo_scip]") {
  const auto dir = std::filesystem::temp_directory_path() / "tessera_hokuyo_test";
  std::filesystem::create_directories(dir);
  EmulatorHostOptions ho;
  ho.link = (dir / "urg").string();
  Device dev(ho);
  HokuyoDriverOptions o;
  o.device = dev.host.devicePath();
  o.retry_initial_s = 0.1;
  o.client.scan_timeout_s = 0.5;
  Caught c;
  bool went_silent = false, spoke_again = false, unplugged = false;
  std::size_t before_unplug = 0;
  const auto report = runDriver(
      o, c, [&](const ScanCatcher& s) { return unplugged && s.count() >= before_unplug + 5; }, 20,
      [&](double t, const ScanCatcher& now) {
        if (!went_silent && now.count() >= 5) {
          dev.host.withDevice([&] { dev.device.faults().silent = true; });
          went_silent = true;
        } else if (went_silent && !spoke_again && t > 2.5) {
          dev.host.withDevice([&] { dev.device.faults().silent = false; });
          spoke_again = true;
        } else if (spoke_again && !unplugged && now.count() >= 10) {
          before_unplug = now.count();
          dev.host.unplug(0.5);
          unplugged = true;
        }
      });
  REQUIRE(unplugged);
  CHECK(c.count() >= before_unplug + 5);
  checkAllGenuineInOrder(c);
  CHECK(figure(report, "reconnects") >= 2);
  CHECK(figure(report, "sessions") >= 3);
  CHECK(dev.host.plugs() == 2);
}

TEST_CASE("hokuyo_scip at the wrong baud rate reports it and publishes nothing",
          "[drivers][hokuyo_scip]") {
  EmulatorHostOptions ho;
  ho.baud = 19200;  // an RS-232 URG-04LX at power-up
  Device dev(ho);
  HokuyoDriverOptions o;
  o.device = dev.host.devicePath();
  o.client.reply_timeout_s = 0.3;
  o.retry_initial_s = 0.1;
  Caught c;
  const auto report = runDriver(
      o, c, [](const ScanCatcher&) { return false; }, 1.5);
  CHECK(c.count() == 0);
  CHECK(figure(report, "reconnects") >= 1);
  CHECK_THAT(std::get<std::string>(driverSummary(report).at("last_error")),
             Catch::Contains("wrong baud rate"));

  // At the device's rate it streams.
  o.baud = 19200;
  runDriver(
      o, c, [](const ScanCatcher& s) { return s.count() >= 3; }, 10);
  CHECK(c.count() >= 3);
}

TEST_CASE("hokuyo_scip without its device keeps retrying and stops when asked",
          "[drivers][hokuyo_scip]") {
  HokuyoDriverOptions o;
  o.device = "/dev/tessera-no-such-laser";
  o.retry_initial_s = 0.05;
  o.retry_max_s = 0.2;
  Caught c;
  const auto t0 = std::chrono::steady_clock::now();
  const auto report = runDriver(
      o, c, [](const ScanCatcher&) { return false; }, 1.0);
  CHECK(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < 3.0);
  CHECK(figure(report, "open_failures") >= 3);
  CHECK_THAT(std::get<std::string>(driverSummary(report).at("last_error")),
             Catch::Contains("No such file"));
}

TEST_CASE("hokuyo_scip refuses bad options and the simulated clock", "[drivers][hokuyo_scip]") {
  HokuyoDriverOptions o;
  o.baud = 12345;
  CHECK_THROWS_WITH(HokuyoDriverActor(o), Catch::Contains("'baud'"));
  o = {};
  o.mount = {0, std::nan("")};
  CHECK_THROWS_WITH(HokuyoDriverActor(o), Catch::Contains("'mount'"));
  o = {};
  o.client.cluster = 200;
  CHECK_THROWS_WITH(HokuyoDriverActor(o), Catch::Contains("cluster"));
  o = {};
  o.device = "";
  CHECK_THROWS_WITH(HokuyoDriverActor(o), Catch::Contains("'device'"));
  RuntimeOptions ro;
  ro.manual = true;
  ro.show_progress = false;
  Runtime rt(ro);
  rt.add("laser", std::make_unique<HokuyoDriverActor>(HokuyoDriverOptions{}));
  CHECK_THROWS_WITH(rt.configure(true), Catch::Contains("clock: wall"));
}

}  // namespace hokuyo_driver_actor_test
