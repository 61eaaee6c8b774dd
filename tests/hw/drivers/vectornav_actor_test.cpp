// vectornav against the emulated VN-100 on a pseudo-terminal, in a real runtime on the wall
// clock: found at its factory 115200 baud and switched to 230400, VNIMU at 100 Hz with the yaw
// rate's sign and value; garbage and corrupted bytes never publish a wrong sample; unplugged (it
// comes back at 115200) and found again; refused options.
#include <tessera/drivers/emulator_host.hpp>
#include <tessera/drivers/vectornav_actor.hpp>
#include <tessera/drivers/vectornav_device.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/runtime.hpp>

#include <catch2/catch.hpp>

#include <chrono>
#include <filesystem>
#include <mutex>
#include <thread>

namespace vectornav_actor_test {

using namespace tessera;
using namespace tessera::drivers;

/// What the emulated IMU feels: turning left at 0.5 rad/s, tilted a little, with these exact
/// values on every sample (no noise).
constexpr std::array<double, 3> kRate{0.01, -0.02, 0.5}, kForce{0.25, -0.5, 9.75};

class Catcher final : public Actor {
 public:
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::ImuSample>(
        "imu", MailboxPolicy::reliable(100000), [this](const Message<msg::ImuSample>& m) {
          const bool exact =
              m->getAngularVelocityX() == kRate[0] && m->getAngularVelocityY() == kRate[1] &&
              m->getAngularVelocityZ() == kRate[2] && m->getLinearAccelerationX() == kForce[0] &&
              m->getLinearAccelerationY() == kForce[1] && m->getLinearAccelerationZ() == kForce[2];
          const Nanos stamp = m->getHeader().getStampNs();
          std::lock_guard lock(mutex);
          if (!exact) ++wrong;
          if (stamp <= last_stamp) ++out_of_order;
          if (m->getHeader().getFrameId() != "imu") ++wrong_frame;
          last_stamp = stamp;
          ++count;
        });
  }
  std::int64_t seen() const {
    std::lock_guard lock(mutex);
    return count;
  }
  mutable std::mutex mutex;
  std::int64_t count = 0, wrong = 0, out_of_order = 0, wrong_frame = 0;
  Nanos last_stamp = 0;
};

TEST_CASE("vectornav streams an emulated VN-100 at 100 Hz and finds it again after unplugging",
          "[drivers][vectornav]") {
  VectorNavDevice device(115200);
  device.motion().angular_velocity = kRate;
  device.motion().specific_force = kForce;
  const auto dir = std::filesystem::temp_directory_path() / "tessera_vectornav_test";
  std::filesystem::create_directories(dir);
  EmulatorHost host(
      {[&](std::string_view b, std::int64_t t) { device.receive(b, t); },
       [&](std::int64_t t) { return device.poll(t); }, [&] { return device.nextDue(); },
       [&](std::int64_t t) { device.restart(t); }, [&] { return device.baud(); }},
      EmulatorHostOptions{(dir / "vn100").string(), -1, 115200});
  VectorNavActorOptions o;
  o.device = host.devicePath();
  o.baud = 230400;
  o.retry_initial_s = 0.05;
  RuntimeOptions ro;
  ro.clock = ClockKind::kWall;
  ro.threads = 2;
  ro.show_progress = false;
  Runtime rt(ro);
  rt.add("imu", std::make_unique<VectorNavActor>(o));
  auto& c = static_cast<Catcher&>(rt.add("catcher", std::make_unique<Catcher>()));
  RunReport report;
  std::thread runner([&] { report = rt.run(); });
  const auto waitFor = [&c](std::int64_t n, double seconds) {
    for (int i = 0; i < seconds * 50 && c.seen() < n; ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
  };
  waitFor(1, 10);
  const std::int64_t first = c.seen();
  const auto t0 = std::chrono::steady_clock::now();
  std::this_thread::sleep_for(std::chrono::milliseconds(1000));
  const double rate = static_cast<double>(c.seen() - first) /
                      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // Damage on the line: dropped, never published.
  host.withDevice([&] {
    device.faults().garbage_probability = 0.3;
    device.faults().corrupt_probability = 0.3;
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(1000));
  host.withDevice([&] { device.faults() = {}; });
  // Unplugged: it comes back at 115200, streaming VNYMR at 40 Hz, and the driver finds it again.
  const std::int64_t before = c.seen();
  host.unplug(0.3);
  waitFor(before + 100, 15);
  const std::int64_t after = c.seen();
  rt.requestStop();
  runner.join();
  CHECK(first >= 1);
  CHECK(rate > 80);  // 100 Hz, less the scheduling of a busy machine
  CHECK(rate < 110);
  CHECK(after >= before + 100);
  CHECK(c.wrong == 0);
  CHECK(c.out_of_order == 0);
  CHECK(c.wrong_frame == 0);
  // The emulator's thread still runs the device: read it under the host's lock.
  CHECK(host.withDevice([&] { return device.baud(); }) == 230400);
  CHECK(host.withDevice([&] { return device.outputType(); }) == vn::kTypeImu);
  const auto& s = report.actors.at(0).summary;
  CHECK(std::get<std::int64_t>(s.at("baud")) == 230400);
  CHECK(std::get<std::int64_t>(s.at("reconnects")) >= 1);
  CHECK(std::get<std::int64_t>(s.at("sessions")) >= 2);
  CHECK(std::get<std::int64_t>(s.at("bad_lines")) > 0);
  CHECK(std::get<std::int64_t>(s.at("samples")) == c.count);
  CHECK(std::get<std::string>(s.at("model")) == "VN-100T-CR, serial 0100012345");
}

TEST_CASE("vectornav refuses options the VN-100 does not have and the simulated clock",
          "[drivers][vectornav]") {
  VectorNavActorOptions o;
  o.imu.rate_hz = 30;
  CHECK_THROWS_WITH(VectorNavActor(o), Catch::Contains("'imu'") && Catch::Contains("rate_hz"));
  o = {};
  o.baud = 128000;
  CHECK_THROWS_WITH(VectorNavActor(o), Catch::Contains("'baud'"));
  o = {};
  o.imu.output = vn::Output::kYmr;  // 100 Hz of VNYMR needs more than 115200 baud
  CHECK_THROWS_WITH(VectorNavActor(o),
                    Catch::Contains("'baud'") && Catch::Contains("cannot carry"));
  o.baud = 230400;
  CHECK_NOTHROW(VectorNavActor(o));
  RuntimeOptions ro;
  ro.manual = true;
  ro.show_progress = false;
  Runtime rt(ro);
  rt.add("imu", std::make_unique<VectorNavActor>(VectorNavActorOptions{}));
  CHECK_THROWS_WITH(rt.configure(true), Catch::Contains("clock: wall"));
}

}  // namespace vectornav_actor_test
