// create_base against the emulated Create 2 on a pseudo-terminal, in a real runtime on the wall
// clock: base_cmd drives the wheels and wheel_ticks count them; the watchdog and the bumper stop
// them with their reasons on base_status; an unplugged robot is found again.
#include <tessera/drivers/create_base_actor.hpp>
#include <tessera/drivers/create_device.hpp>
#include <tessera/drivers/emulator_host.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/runtime.hpp>

#include <catch2/catch.hpp>

#include <chrono>
#include <filesystem>
#include <mutex>
#include <numbers>
#include <thread>

namespace create_base_actor_test {

using namespace tessera;
using namespace tessera::drivers;

class Listener final : public Actor {
 public:
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::WheelTicks>("wheel_ticks", MailboxPolicy::reliable(10000),
                                   [this](const Message<msg::WheelTicks>& m) {
                                     std::lock_guard lock(mutex);
                                     left = m->getLeft();
                                     ++ticks;
                                   });
    ctx.subscribe<msg::BaseStatus>("base_status", MailboxPolicy::reliable(10000),
                                   [this](const Message<msg::BaseStatus>& m) {
                                     std::lock_guard lock(mutex);
                                     reason = m->getStopReason().cStr();
                                     bumped = m->getBumpLeft();
                                     voltage = m->getBatteryVoltage();
                                   });
  }
  mutable std::mutex mutex;
  std::int64_t left = 0, ticks = 0;
  std::string reason;
  bool bumped = false;
  double voltage = 0;
};

TEST_CASE("create_base drives an emulated Create 2, stops it on its watchdog and bumper",
          "[drivers][create_base]") {
  CreateDevice device;
  EmulatorHost host(
      {[&](std::string_view b, std::int64_t t) { device.receive(b, t); },
       [&](std::int64_t t) { return device.poll(t); },
       [&] { return device.nextDue(); },
       [&](std::int64_t t) { device.restart(t); },
       {}},
      EmulatorHostOptions{(std::filesystem::temp_directory_path() / "tessera_create_test").string(),
                          -1, 115200});
  CreateBaseActorOptions o;
  o.device = host.devicePath();
  o.retry_initial_s = 0.05;
  o.base.watchdog_s = 0.3;
  RuntimeOptions ro;
  ro.clock = ClockKind::kWall;
  ro.threads = 2;
  ro.show_progress = false;
  Runtime rt(ro);
  auto cmd = rt.externalPublisher<msg::Twist>("base_cmd");
  rt.add("base", std::make_unique<CreateBaseActor>(o));
  auto& l = static_cast<Listener&>(rt.add("listener", std::make_unique<Listener>()));
  RunReport report;
  std::thread runner([&] { report = rt.run(); });
  const auto send = [&](double vx, double omega, int times) {
    for (int i = 0; i < times; ++i) {
      auto loan = cmd.loan();
      auto b = loan.builder();
      setHeader(b.initHeader(), 0, "base_link", cmd.nextSeq());
      b.initTwist().setVx(vx);
      b.getTwist().setOmega(omega);
      cmd.publish(std::move(loan));
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  };
  const auto wait = [](int ms) { std::this_thread::sleep_for(std::chrono::milliseconds(ms)); };
  // The device runs on the host's thread: read it under the host's lock.
  const auto speed = [&] { return host.withDevice([&] { return device.rightSpeed(); }); };
  const auto snapshot = [&l] {
    std::lock_guard lock(l.mutex);
    return std::make_pair(l.left, l.reason);
  };
  wait(300);
  const auto start = snapshot().first;
  send(0.2, 0, 20);  // 1 s at 0.2 m/s
  const double counts_per_m = 508.8 / (std::numbers::pi * 0.072);
  const double moved = (snapshot().first - start) / counts_per_m;
  CHECK(speed() == Approx(200));
  wait(500);  // no command: the watchdog stops it
  CHECK(speed() == 0);
  CHECK_THAT(snapshot().second, Catch::Contains("watchdog"));
  send(0.2, 0, 4);
  host.withDevice([&] { device.world().bump_left = true; });
  wait(100);
  CHECK(speed() == 0);
  send(0.2, 0, 2);  // refused while pressed
  CHECK(speed() == 0);
  CHECK_THAT(snapshot().second, Catch::Contains("bumper left"));
  host.withDevice([&] { device.world().bump_left = false; });
  // Unplugged: the robot restarts (Off); the driver reconnects and starts it again.
  host.unplug(0.2);
  wait(1500);
  send(0.1, 0, 4);
  CHECK(speed() == Approx(100));
  rt.requestStop();
  runner.join();
  CHECK(moved == Approx(0.2).margin(0.06));
  const auto& s = report.actors.at(0).summary;
  CHECK(std::get<std::int64_t>(s.at("watchdog_stops")) >= 1);
  CHECK(std::get<std::int64_t>(s.at("safety_stops")) == 1);
  CHECK(std::get<std::int64_t>(s.at("reconnects")) >= 1);
  CHECK(l.voltage == Approx(14.8));
}

TEST_CASE("create_base refuses bad options and the simulated clock", "[drivers][create_base]") {
  CreateBaseActorOptions o;
  o.baud = 57600;
  CHECK_THROWS_WITH(CreateBaseActor(o), Catch::Contains("'baud'"));
  o = {};
  o.base.max_speed_m_s = 2;
  CHECK_THROWS_WITH(CreateBaseActor(o), Catch::Contains("'base'"));
  RuntimeOptions ro;
  ro.manual = true;
  ro.show_progress = false;
  Runtime rt(ro);
  rt.add("base", std::make_unique<CreateBaseActor>(CreateBaseActorOptions{}));
  CHECK_THROWS_WITH(rt.configure(true), Catch::Contains("clock: wall"));
}

}  // namespace create_base_actor_test
